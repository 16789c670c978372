// SPDX-License-Identifier: Apache-2.0
// The use-case layer called as a C++ program would call it (no binary): each job against the
// algorithm it wraps, its outputs on disk read back with OpenVDB's own reader, and its errors:
// typed (ParamError with the parameter's id, SceneError, IoError), worded without any CLI
// option, and leaving no file behind.
#include <ivdb/jobs/Bench.h>
#include <ivdb/jobs/Combine.h>
#include <ivdb/jobs/Convert.h>
#include <ivdb/jobs/Differentiate.h>
#include <ivdb/jobs/Info.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/jobs/Visualize.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/ops/Csg.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using namespace ivdb;

class TestJobs: public ivdb::test::TempDirTest
{
protected:
    TestJobs(): TempDirTest("jobs") {}

    static std::string data(const std::string& name) { return std::string(IVDB_DATA_DIR) + "/" + name; }

    void writeText(const std::string& name, const std::string& text) const
    {
        std::ofstream(path(name)) << text;
    }

    /// Every grid of a file, read back with OpenVDB's own reader.
    static openvdb::GridPtrVec readBack(const std::string& file)
    {
        openvdb::io::File f(file);
        f.open();
        openvdb::GridPtrVec grids = *f.getGrids();
        f.close();
        return grids;
    }

    /// Rasterize @a scene (a data/ file) into @a out.
    jobs::RasterizeResult rasterize(const std::string& scene, const std::string& out) const
    {
        jobs::RasterizeOptions o;
        o.scene = data(scene);
        o.output = out.empty() ? "" : path(out);
        return jobs::rasterize(o);
    }

    /// @a job throws a ParamError for parameter @a param whose message has no CLI word, and
    /// leaves no file in the folder but @a keep.
    void expectParamError(const std::function<void()>& job, const std::string& param,
                          const std::vector<std::string>& keep = {}) const
    {
        try {
            job();
            ADD_FAILURE() << "no error for " << param;
        } catch (const ParamError& e) {
            EXPECT_EQ(e.param(), param) << e.what();
            EXPECT_EQ(std::string(e.what()).find("--"), std::string::npos) << e.what();
            EXPECT_FALSE(e.reason().empty());
        }
        for (const auto& entry : fs::directory_iterator(mDir)) {
            const std::string name = entry.path().filename().string();
            EXPECT_NE(std::find(keep.begin(), keep.end(), name), keep.end())
                << param << ": left " << name;
        }
    }

    static void expectSameGrid(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b)
    {
        ASSERT_EQ(a.activeVoxelCount(), b.activeVoxelCount());
        auto acc = b.getConstAccessor();
        for (auto it = a.cbeginValueOn(); it; ++it) {
            float v;
            ASSERT_TRUE(acc.probeValue(it.getCoord(), v)) << it.getCoord();
            ASSERT_EQ(*it, v) << it.getCoord();
        }
    }

};

TEST_F(TestJobs, RasterizeWritesWhatTheRasterizerMakes)
{
    const jobs::RasterizeResult r = rasterize("sphere.json", "s.vdb");
    // The same settings and grid as the scene through scene:: and raster:: directly.
    const scene::Scene sc = scene::loadScene(data("sphere.json"));
    const raster::RasterSettings s = jobs::sceneSettings(sc, data("sphere.json"));
    EXPECT_EQ(r.settings.voxelSize, 0.01);
    EXPECT_EQ(r.settings.halfWidth, 3.0);
    expectSameGrid(*r.surface, *raster::rasterize(sc.shape, s));
    EXPECT_EQ(r.density, nullptr);
    EXPECT_EQ(r.fileBytes, fs::file_size(path("s.vdb")));
    const openvdb::GridPtrVec back = readBack(path("s.vdb"));
    ASSERT_EQ(back.size(), 1u);
    expectSameGrid(*r.surface, *openvdb::gridPtrCast<openvdb::FloatGrid>(back[0]));
    EXPECT_EQ(back[0]->metaValue<std::string>("ivdb_source"), data("sphere.json"));
    EXPECT_NE(back[0]->metaValue<std::string>("ivdb_scene").find("\"voxel_size\":0.01"),
              std::string::npos);

    // In memory only (no output), with overrides and a fog volume.
    jobs::RasterizeOptions o;
    o.scene = data("sphere.json");
    o.voxelSize = 0.02;
    o.halfWidth = 2.0;
    o.fog = true;
    const jobs::RasterizeResult m = jobs::rasterize(o);
    EXPECT_EQ(m.fileBytes, 0u);
    EXPECT_EQ(m.surface->voxelSize()[0], 0.02);
    EXPECT_FLOAT_EQ(m.surface->background(), 0.04f);
    ASSERT_NE(m.density, nullptr);
    EXPECT_EQ(m.density->getGridClass(), openvdb::GRID_FOG_VOLUME);
    EXPECT_EQ(m.density->getName(), "density");
    EXPECT_EQ(std::vector<fs::path>(fs::directory_iterator(mDir), {}).size(), 1u); // s.vdb only
}

TEST_F(TestJobs, RasterizeErrorsNameTheParameterOrTheSceneField)
{
    jobs::RasterizeOptions o;
    o.scene = data("sphere.json");
    o.output = path("out.vdb");
    o.voxelSize = -1.0;
    expectParamError([&] { jobs::rasterize(o); }, "voxel_size");
    o.voxelSize.reset();
    o.halfWidth = 0.5;
    expectParamError([&] { jobs::rasterize(o); }, "half_width");

    // No voxel size anywhere: missing, with the scene file as context.
    writeText("novoxel.json", R"({"shape": {"type": "sphere", "radius": 1}})");
    o.halfWidth.reset();
    o.scene = path("novoxel.json");
    try {
        jobs::rasterize(o);
        ADD_FAILURE() << "no error";
    } catch (const ParamError& e) {
        EXPECT_EQ(e.kind(), ParamError::Kind::Missing);
        EXPECT_EQ(e.param(), "voxel_size");
        EXPECT_EQ(e.context(), path("novoxel.json"));
        EXPECT_NE(e.describe("--voxel-size").find("(--voxel-size)"), std::string::npos);
        EXPECT_EQ(std::string(e.what()).find("--"), std::string::npos) << e.what();
    }
    // A voxel size from the scene that OpenVDB refuses is the scene file's error, by its key.
    writeText("tiny.json", R"({"voxel_size": 1e-6, "shape": {"type": "sphere", "radius": 1}})");
    o.scene = path("tiny.json");
    try {
        jobs::rasterize(o);
        ADD_FAILURE() << "no error";
    } catch (const scene::SceneError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("tiny.json: voxel_size:"), std::string::npos) << what;
        EXPECT_EQ(what.find("--"), std::string::npos) << what;
    }
    // The same voxel size given by the caller is the caller's parameter.
    o.voxelSize = 1e-6;
    expectParamError([&] { jobs::rasterize(o); }, "voxel_size", {"novoxel.json", "tiny.json"});
    EXPECT_FALSE(fs::exists(path("out.vdb")));
}

TEST_F(TestJobs, CombineIsTheGridOperation)
{
    rasterize("inputs/sphere_left.json", "a.vdb");
    rasterize("inputs/sphere_right.json", "b.vdb");
    const auto a = jobs::readLevelSet(path("a.vdb")), b = jobs::readLevelSet(path("b.vdb"));

    jobs::CombineOptions o;
    o.inputs = {path("a.vdb"), path("b.vdb")};
    o.output = path("u.vdb");
    for (implicit::CsgOp op : {implicit::CsgOp::Union, implicit::CsgOp::Intersection,
                               implicit::CsgOp::Difference}) {
        o.op = op;
        const jobs::CombineResult r = jobs::combine(o);
        expectSameGrid(*r.surface, *ops::csg(op, {a, b}));
        EXPECT_TRUE(r.warnings.empty());
        expectSameGrid(*r.surface, *openvdb::gridPtrCast<openvdb::FloatGrid>(readBack(path("u.vdb"))[0]));
    }
    o.op = implicit::CsgOp::Union;
    o.p = 50.0;
    const jobs::CombineResult blended = jobs::combine(o);
    ops::BlendSettings bs;
    bs.p = 50.0;
    expectSameGrid(*blended.surface, *ops::blend(implicit::CsgOp::Union, {a, b}, bs));
    ASSERT_EQ(blended.notes.size(), 1u);
    EXPECT_NE(blended.notes[0].find("bands extended"), std::string::npos) << blended.notes[0];
    EXPECT_EQ(readBack(path("u.vdb"))[0]->metaValue<std::string>("ivdb_source"),
              "blend union p=50 " + path("a.vdb") + " " + path("b.vdb"));

    // Spheres that do not meet: an empty intersection is a warning, not an error.
    writeText("far.json", R"({"voxel_size": 0.01, "shape": {"type": "sphere", "center": [5, 0, 0], "radius": 0.5}})");
    jobs::RasterizeOptions far;
    far.scene = path("far.json");
    far.output = path("far.vdb");
    jobs::rasterize(far);
    jobs::CombineOptions apart;
    apart.op = implicit::CsgOp::Intersection;
    apart.inputs = {path("a.vdb"), path("far.vdb")};
    const jobs::CombineResult empty = jobs::combine(apart);
    EXPECT_EQ(empty.surface->activeVoxelCount(), 0u);
    ASSERT_EQ(empty.warnings.size(), 1u);
    EXPECT_NE(empty.warnings[0].find("no surface"), std::string::npos);

    const std::vector<std::string> keep{"a.vdb", "b.vdb", "u.vdb", "far.json", "far.vdb"};
    jobs::CombineOptions bad = o;
    bad.output = path("bad.vdb");
    bad.p = 2000.0;
    expectParamError([&] { jobs::combine(bad); }, "p", keep);
    bad.p = 50.0;
    bad.tolerance = 0.0;
    expectParamError([&] { jobs::combine(bad); }, "tolerance", keep);
    bad.tolerance = 0.05;
    bad.inputs = {path("a.vdb")};
    expectParamError([&] { jobs::combine(bad); }, "inputs", keep);
    bad.inputs = {path("a.vdb"), path("b.vdb")};
    bad.grid = "nothing";
    expectParamError([&] { jobs::combine(bad); }, "grid", keep);
}

TEST_F(TestJobs, GradientAndCurvatureAreTheOperators)
{
    rasterize("sphere.json", "s.vdb");
    const auto phi = jobs::readLevelSet(path("s.vdb"));

    jobs::GradientOptions g;
    g.input = path("s.vdb");
    g.output = path("g.vdb");
    g.step = 2;
    g.magnitude = true;
    g.withInput = true;
    const jobs::GradientResult gr = jobs::gradient(g);
    const auto expected = diff::gradient(*phi, 2);
    ASSERT_EQ(gr.gradient->activeVoxelCount(), expected->activeVoxelCount());
    auto acc = expected->getConstAccessor();
    for (auto it = gr.gradient->cbeginValueOn(); it; ++it) ASSERT_EQ(*it, acc.getValue(it.getCoord()));
    ASSERT_NE(gr.magnitude, nullptr);
    std::vector<std::string> names;
    for (const auto& grid : readBack(path("g.vdb"))) names.push_back(grid->getName());
    std::sort(names.begin(), names.end());
    EXPECT_EQ(names, (std::vector<std::string>{"gradient", "gradient_magnitude", "surface"}));

    jobs::CurvatureOptions c;
    c.input = path("s.vdb");
    c.method = jobs::CurvatureMethod::Principal;
    const jobs::CurvatureResult cr = jobs::curvature(c);
    ASSERT_EQ(cr.grids.size(), 2u);
    EXPECT_EQ(cr.grids[0]->getName(), "k1");
    EXPECT_EQ(cr.grids[1]->getName(), "k2");
    c.method = jobs::CurvatureMethod::Mean;
    expectSameGrid(*jobs::curvature(c).grids[0], *diff::curvature(*phi, diff::Curvature::Mean));

    const std::vector<std::string> keep{"s.vdb", "g.vdb"};
    jobs::GradientOptions bad = g;
    bad.output = path("bad.vdb");
    bad.step = 21;
    expectParamError([&] { jobs::gradient(bad); }, "step", keep);
    bad.step = 1;
    bad.grid = "density";
    expectParamError([&] { jobs::gradient(bad); }, "grid", keep);
    // A vector grid where a level set is needed: the grid parameter, with the file as context.
    bad.input = path("g.vdb");
    bad.grid = "gradient";
    try {
        jobs::gradient(bad);
        ADD_FAILURE() << "no error";
    } catch (const ParamError& e) {
        EXPECT_EQ(e.param(), "grid");
        EXPECT_NE(std::string(e.what()).find(path("g.vdb") + ": grid 'gradient'"), std::string::npos) << e.what();
    }

    jobs::CompareGradientOptions cmp;
    cmp.scene = data("sphere.json");
    cmp.voxelSize = 0.05;
    cmp.steps = {1, 2};
    const jobs::CompareGradientResult r = jobs::compareGradient(cmp);
    ASSERT_EQ(r.steps.size(), 2u);
    EXPECT_EQ(r.steps[1].first, 2);
    // A sphere's distance field: the discrete gradient is within a degree of the analytic one.
    EXPECT_LT(r.steps[0].second.interior.angleDeg.p95, 1.0);
    cmp.steps = {0};
    expectParamError([&] { jobs::compareGradient(cmp); }, "step", keep);
}

// The CLI's gradient and curvature (keepGrids false) compute, compress and write a run of 8192
// leaves at a time: the file must be the one the whole grids make, byte for byte but the UUID
// (36 bytes from offset 21), on a sphere of more than two runs, with each grid kind and option.
TEST_F(TestJobs, StreamedGradientAndCurvatureWriteTheSameFile)
{
    jobs::RasterizeOptions ro;
    ro.scene = data("sphere.json");
    ro.output = path("s.vdb");
    ro.voxelSize = 0.004;
    jobs::rasterize(ro);
    const auto phi = jobs::readLevelSet(path("s.vdb"));
    ASSERT_GT(phi->tree().leafCount(), 2u * 8192u);
    auto bytes = [this](const std::string& name) {
        std::ifstream in(path(name), std::ios::binary);
        std::string b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        EXPECT_GT(b.size(), 100u) << name;
        return b.size() > 57 ? b.substr(0, 21) + b.substr(57) : b;
    };
    struct GradientCase
    {
        bool magnitude, withInput;
        io::Compression compression;
        bool half;
    };
#ifdef IVDB_SANITIZED
    // Sanitized builds run 10-20x slower: one case of each command.
    const std::vector<GradientCase> kGradients{{true, true, io::Compression::Blosc, false}};
    const std::vector<jobs::CurvatureMethod> kCurvatures{jobs::CurvatureMethod::Mean};
#else
    const std::vector<GradientCase> kGradients{{true, true, io::Compression::Blosc, false},
                                               {false, false, io::Compression::Zip, true},
                                               {false, true, io::Compression::None, false}};
    const std::vector<jobs::CurvatureMethod> kCurvatures{jobs::CurvatureMethod::Principal,
                                                         jobs::CurvatureMethod::Mean};
#endif
    for (const GradientCase& gc : kGradients) {
        jobs::GradientOptions g;
        g.input = path("s.vdb");
        g.magnitude = gc.magnitude;
        g.withInput = gc.withInput;
        g.write.compression = gc.compression;
        g.write.half = gc.half;
        g.output = path("whole.vdb");
        const jobs::GradientResult whole = jobs::gradient(g);
        g.output = path("runs.vdb");
        g.keepGrids = false;
        const jobs::GradientResult runs = jobs::gradient(g);
        EXPECT_EQ(runs.gradient, nullptr);
        EXPECT_EQ(runs.activeVoxels, whole.activeVoxels);
        EXPECT_EQ(whole.activeVoxels, std::uint64_t(phi->activeVoxelCount()));
        EXPECT_TRUE(bytes("runs.vdb") == bytes("whole.vdb"))
            << "gradient, magnitude " << gc.magnitude << ", input " << gc.withInput
            << ", compression " << int(gc.compression) << ", half " << gc.half;
    }
    for (const auto method : kCurvatures) {
        jobs::CurvatureOptions c;
        c.input = path("s.vdb");
        c.method = method;
        c.withInput = method == jobs::CurvatureMethod::Mean;
        c.output = path("whole.vdb");
        const jobs::CurvatureResult whole = jobs::curvature(c);
        c.output = path("runs.vdb");
        c.keepGrids = false;
        const jobs::CurvatureResult runs = jobs::curvature(c);
        EXPECT_TRUE(runs.grids.empty());
        EXPECT_EQ(runs.activeVoxels, whole.activeVoxels);
        EXPECT_TRUE(bytes("runs.vdb") == bytes("whole.vdb")) << "curvature " << int(method);
    }
    // Read back by OpenVDB: the streamed gradient is the operator's.
    const auto expected = diff::gradient(*phi, 1);
    jobs::GradientOptions g;
    g.input = path("s.vdb");
    g.output = path("runs.vdb");
    g.keepGrids = false;
    jobs::gradient(g);
    const auto back = openvdb::gridPtrCast<openvdb::Vec3SGrid>(readBack(path("runs.vdb"))[0]);
    ASSERT_TRUE(back);
    ASSERT_EQ(back->activeVoxelCount(), expected->activeVoxelCount());
    auto acc = expected->getConstAccessor();
    for (auto it = back->cbeginValueOn(); it; ++it) ASSERT_EQ(*it, acc.getValue(it.getCoord()));
}

TEST_F(TestJobs, ConvertKeepsTheGridsAndChecksTheFormat)
{
    rasterize("sphere.json", "s.vdb");
    const auto phi = jobs::readLevelSet(path("s.vdb"));
    jobs::ConvertOptions c;
    c.input = path("s.vdb");
    c.output = path("z.vdb");
    c.compression = io::Compression::None;
    const jobs::ConvertResult r = jobs::convert(c);
    EXPECT_EQ(r.format, jobs::FileFormat::Vdb);
    ASSERT_EQ(r.grids.size(), 1u);
    const auto back = readBack(path("z.vdb"));
    ASSERT_EQ(back.size(), 1u);
    expectSameGrid(*phi, *openvdb::gridPtrCast<openvdb::FloatGrid>(back[0]));
    EXPECT_GT(r.fileBytes, 0u);
    c.output = path("s.nvdb");
    c.compression.reset();
    EXPECT_EQ(jobs::convert(c).format, jobs::FileFormat::NanoVdb);
    EXPECT_GT(fs::file_size(path("s.nvdb")), 0u);

    const std::vector<std::string> keep{"s.vdb", "z.vdb", "s.nvdb"};
    jobs::ConvertOptions bad = c;
    bad.output = path("s.png");
    expectParamError([&] { jobs::convert(bad); }, "output", keep);
    bad.output = path("t.nvdb");
    bad.half = true;
    expectParamError([&] { jobs::convert(bad); }, "half", keep);
    bad.half = false;
    bad.compression = io::Compression::Zip;
    expectParamError([&] { jobs::convert(bad); }, "compression", keep);
    bad.compression.reset();
    bad.grid = "nope";
    expectParamError([&] { jobs::convert(bad); }, "grid", keep);
}

TEST_F(TestJobs, VisualizeJobsCheckTheirParameters)
{
    rasterize("sphere.json", "s.vdb");
    jobs::GradientOptions g;
    g.input = path("s.vdb");
    g.output = path("g.vdb");
    g.withInput = true;
    jobs::gradient(g);
    const std::vector<std::string> keep{"s.vdb", "g.vdb"};

    jobs::MeshOptions m;
    m.input = path("s.vdb");
    m.output = path("m.stl");
    expectParamError([&] { jobs::mesh(m); }, "output", keep);
    m.output = path("m.ply");
    m.adaptivity = 2.0;
    expectParamError([&] { jobs::mesh(m); }, "adaptivity", keep);
    m.adaptivity = 0.0;
    m.colormap = "jet";
    expectParamError([&] { jobs::mesh(m); }, "colormap", keep);
    m.colormap.reset();
    m.colorBy = path("g.vdb") + ":gradient";
    m.range = std::make_pair(0.0, 1.0);
    expectParamError([&] { jobs::mesh(m); }, "range", keep);
    m.range.reset();
    const jobs::MeshResult mr = jobs::mesh(m);
    // A closed mesh of the unit sphere: its volume within 1% of 4/3 pi.
    EXPECT_NEAR(mr.enclosedVolume, 4.18879, 0.01 * 4.18879);

    jobs::GlyphsOptions gl;
    gl.input = path("g.vdb");
    gl.output = path("a.obj");
    gl.stride = 0;
    expectParamError([&] { jobs::glyphs(gl); }, "stride", {"s.vdb", "g.vdb", "m.ply"});
    gl.stride = 8;
    const jobs::GlyphsResult gr = jobs::glyphs(gl);
    EXPECT_GT(gr.arrows, 0u);
    EXPECT_EQ(gr.field, "gradient");
    EXPECT_DOUBLE_EQ(gr.length, 2.0 * 8 * 0.01);
    gl.input = path("s.vdb");
    expectParamError([&] { jobs::glyphs(gl); }, "grid", {"s.vdb", "g.vdb", "m.ply", "a.obj"});

    jobs::RenderOptions r;
    r.input = path("s.vdb");
    r.output = path("r.png");
    r.width = 0;
    expectParamError([&] { jobs::render(r); }, "size", {"s.vdb", "g.vdb", "m.ply", "a.obj"});
    r.width = 40;
    r.height = 30;
    r.camera.fov = 180.0;
    expectParamError([&] { jobs::render(r); }, "fov", {"s.vdb", "g.vdb", "m.ply", "a.obj"});
    r.camera.fov.reset();
    const jobs::RenderResult rr = jobs::render(r);
    EXPECT_GT(rr.surfacePixels, 0u);
    EXPECT_TRUE(fs::exists(path("r.png")));
}

TEST_F(TestJobs, ColorBarLabelNamesTheQuantityAndItsUnits)
{
    writeText("small.json", R"({"voxel_size": 0.05, "shape": {"type": "sphere", "radius": 1}})");
    jobs::RasterizeOptions ro;
    ro.scene = path("small.json");
    ro.fog = true;
    const jobs::RasterizeResult raster = jobs::rasterize(ro);
    ASSERT_TRUE(raster.surface && raster.density);
    EXPECT_EQ(jobs::colorBarLabel(*raster.surface), "surface (length)");
    EXPECT_EQ(jobs::colorBarLabel(*raster.density), "density");
    openvdb::io::File(path("s.vdb")).write({raster.surface});

    // The curvatures' units from the metadata `ivdb curvature` writes.
    const std::vector<std::pair<jobs::CurvatureMethod, std::string>> methods = {
        {jobs::CurvatureMethod::Mean, "curvature (1/length)"},
        {jobs::CurvatureMethod::Gaussian, "curvature (1/length^2)"},
        {jobs::CurvatureMethod::Laplacian, "curvature (1/length)"},
        {jobs::CurvatureMethod::Principal, "k1 (1/length)"}};
    for (const auto& [method, label] : methods) {
        jobs::CurvatureOptions co;
        co.input = path("s.vdb");
        co.method = method;
        const jobs::CurvatureResult k = jobs::curvature(co);
        ASSERT_FALSE(k.grids.empty());
        EXPECT_EQ(jobs::colorBarLabel(*k.grids.front()), label);
    }
    jobs::GradientOptions go;
    go.input = path("s.vdb");
    go.magnitude = true;
    EXPECT_EQ(jobs::colorBarLabel(*jobs::gradient(go).magnitude), "gradient_magnitude");
}

TEST_F(TestJobs, InfoAndBenchSweepInProcess)
{
    rasterize("sphere.json", "s.vdb");
    const std::vector<io::GridInfo> info = jobs::info(path("s.vdb"));
    ASSERT_EQ(info.size(), 1u);
    EXPECT_EQ(info[0].name, "surface");
    EXPECT_TRUE(info[0].isLevelSet);
    EXPECT_EQ(info[0].activeVoxels, jobs::readLevelSet(path("s.vdb"))->activeVoxelCount());

    // A sweep measured in this process (no child processes, no plot): a row per method and
    // resolution, each reported as it is measured.
    jobs::BenchOptions b;
    b.scenes = {data("sphere.json")};
    b.resolutions = {16, 24};
    b.out = path("bench");
    b.reps = 1;
    int reported = 0;
    b.onRow = [&reported](const jobs::BenchRow&) { ++reported; };
    const jobs::BenchResult r = jobs::benchSweep(b);
    ASSERT_EQ(r.rows.size(), 6u); // sparse, dense and openvdb (a sphere) at two resolutions
    EXPECT_EQ(reported, 6);
    for (const auto& row : r.rows) {
        EXPECT_EQ(row.status, "ok") << row.method;
        EXPECT_GT(row.measurement.activeVoxels, 0u);
        EXPECT_GT(row.measurement.fileBytes, 0u);
    }
    // Sparse and dense make the same grid.
    EXPECT_EQ(r.rows[0].measurement.activeVoxels, r.rows[1].measurement.activeVoxels);
    EXPECT_TRUE(fs::exists(r.csvPath));
    EXPECT_TRUE(r.pngPath.empty());
    EXPECT_NE(r.table.find("| sphere | 16 |"), std::string::npos) << r.table;
    EXPECT_EQ(r.machine, util::machineInfo().describe());
    b.reps = 0;
    expectParamError([&] { jobs::benchSweep(b); }, "reps", {"s.vdb", "bench"});
}

// The machine a benchmark names: the CPU's model and the version of the vectorized loops it runs,
// against /proc/cpuinfo read here (the first processor's model name and flags). The loops'
// versions are AVX-512, AVX2 and the x86-64 baseline (src/util/Simd.h), the first the CPU
// supports.
TEST(TestMachine, NamesTheCpuAndTheVectorCodeItsFlagsAllow)
{
    const util::MachineInfo m = util::machineInfo();
    EXPECT_GT(m.cores, 0u);
    std::ifstream in("/proc/cpuinfo");
    if (!in) GTEST_SKIP() << "no /proc/cpuinfo here";
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::smatch name, flags;
    // No model name (some CPUs' kernels give none): "unknown".
    EXPECT_EQ(m.cpu, std::regex_search(text, name, std::regex(R"(model name[ \t]*:[ \t]*([^\n]*\S))"))
                         ? name[1].str() : std::string("unknown"));
    if (m.vectorCode.find("no run-time choice") != std::string::npos) {
        GTEST_SKIP() << "built without per-CPU versions (sanitizers): " << m.vectorCode;
    }
    ASSERT_TRUE(std::regex_search(text, flags, std::regex(R"(\nflags\s*:([^\n]*))")));
    std::istringstream words(flags[1].str());
    std::vector<std::string> has{std::istream_iterator<std::string>(words),
                                 std::istream_iterator<std::string>()};
    auto flag = [&](const char* f) { return std::find(has.begin(), has.end(), f) != has.end(); };
    EXPECT_EQ(m.vectorCode, flag("avx512f") ? "AVX-512" : flag("avx2") ? "AVX2" : "SSE2");
    EXPECT_EQ(m.describe(), m.cpu + ", " + std::to_string(m.cores) + " cores, vector code " +
                                m.vectorCode);
}

} // namespace

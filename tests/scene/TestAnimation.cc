// SPDX-License-Identifier: Apache-2.0
// Keyed scenes: frame ranges and file names, the three interpolations against their closed
// forms, every bad keyed value refused with its JSON path, and a keyed sphere's rasterized
// radius at five frames of a sequence for each interpolation.
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/scene/Animation.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

using namespace ivdb;
using implicit::Vec3d;
using scene::Interpolation;
using scene::Keys;

namespace fs = std::filesystem;

class TestAnimation: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }

    static scene::Scene parseAt(const std::string& text, double frame)
    {
        return scene::parseScene(text, "anim.json", {std::nullopt, std::nullopt, frame});
    }

    /// The message of the SceneError that parsing @a text throws ("" if none).
    static std::string errorOf(const std::string& text)
    {
        try {
            scene::parseScene(text, "anim.json");
        } catch (const scene::SceneError& e) {
            return e.what();
        }
        return "";
    }
};

TEST_F(TestAnimation, FrameRangesAndTheirErrors)
{
    EXPECT_EQ(scene::parseFrameRange("1-48").frames().size(), 48u);
    EXPECT_EQ(scene::parseFrameRange("7").frames(), std::vector<int>({7}));
    EXPECT_EQ(scene::parseFrameRange("0-10:4").frames(), std::vector<int>({0, 4, 8}));
    EXPECT_EQ(scene::parseFrameRange("3-3:5").frames(), std::vector<int>({3}));
    for (const char* bad : {"", "a", "5-2", "1-", "-3", "1-4:0", "1-4:", "1:2", "1-4:2x",
                            "1.5-3", "1 - 3", "1234567890"}) {
        EXPECT_THROW(scene::parseFrameRange(bad), ParamError) << bad;
    }
    try {
        scene::parseFrameRange("5-2");
    } catch (const ParamError& e) {
        EXPECT_EQ(e.param(), "frames");
        EXPECT_NE(std::string(e.what()).find("A > B"), std::string::npos) << e.what();
    }
}

TEST_F(TestAnimation, FileNamesPadEachRunOfHashes)
{
    EXPECT_EQ(scene::frameFileName("out_####.vdb", 7), "out_0007.vdb");
    EXPECT_EQ(scene::frameFileName("out_#.vdb", 123), "out_123.vdb");
    EXPECT_EQ(scene::frameFileName("f##/out_####.vdb", 12), "f12/out_0012.vdb");
    EXPECT_EQ(scene::frameFileName("out.vdb", 3), "out.vdb");
    EXPECT_TRUE(scene::hasFrameField("a#.vdb"));
    EXPECT_FALSE(scene::hasFrameField("a.vdb"));
}

TEST_F(TestAnimation, InterpolationsMatchTheirClosedForms)
{
    Keys k;
    k.frames = {1.0, 11.0, 21.0};
    k.values = {{0.3, -1.0}, {0.5, 2.0}, {0.4, 2.0}};
    for (Interpolation mode : {Interpolation::Linear, Interpolation::Smooth, Interpolation::Step}) {
        k.interpolation = mode;
        // Keys exactly; the end values outside.
        for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(k.at(k.frames[i]), k.values[i]);
        EXPECT_EQ(k.at(-5.0), k.values.front());
        EXPECT_EQ(k.at(100.0), k.values.back());
        for (double f = 1.0; f <= 21.0; f += 0.25) {
            const std::size_t i = f < 11.0 ? 0 : 1;
            double t = (f - k.frames[i]) / 10.0;
            if (mode == Interpolation::Smooth) t = 3 * t * t - 2 * t * t * t;
            for (std::size_t c = 0; c < 2; ++c) {
                const double a = k.values[i][c], b = k.values[i + 1][c];
                const double expected = mode == Interpolation::Step ? (f == 21.0 ? b : a)
                                                                    : a + t * (b - a);
                EXPECT_NEAR(k.at(f)[c], expected, 1e-12) << "frame " << f;
            }
        }
    }
    // Smooth is flat at each key: the slope one hundredth of a frame away is ~0.
    k.interpolation = Interpolation::Smooth;
    EXPECT_LT(std::abs(k.at(11.01)[0] - k.at(11.0)[0]) / 0.01, 1e-3);
    EXPECT_LT(std::abs(k.at(11.0)[0] - k.at(10.99)[0]) / 0.01, 1e-3);
}

TEST_F(TestAnimation, KeyedFieldsResolveBeforeTheShapeIsBuilt)
{
    const std::string text = R"({"frames": {"start": 1, "end": 9},
        "shape": {"type": "transform",
                  "translate": {"keys": [[1, [0, 0, 0]], [9, [0.8, 0, 0]]]},
                  "child": {"type": "blend", "op": "union",
                            "p": {"keys": [[1, 2], [9, 10]], "interpolation": "step"},
                            "children": [{"type": "sphere", "radius": {"keys": [[1, 0.5], [5, 1]]}},
                                         {"type": "quadric", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],
                                          [0,0,0,{"keys": [[1, -1], [9, -4]]}]]}]}}})";
    const scene::Scene s1 = parseAt(text, 1), s5 = parseAt(text, 5), s9 = parseAt(text, 9);
    EXPECT_TRUE(s1.animated);
    ASSERT_TRUE(s1.frames);
    EXPECT_EQ(s1.frames->start, 1);
    EXPECT_EQ(s1.frames->end, 9);
    EXPECT_EQ(s5.frame, 5.0);
    // The resolved scene is stored as plain numbers.
    EXPECT_EQ(s5.json.find("keys"), std::string::npos) << s5.json;
    EXPECT_NE(s5.json.find("[0.4,0.0,0.0]"), std::string::npos) << s5.json;
    // Far along -x only the sphere matters: its radius (1 from frame 5) and the translation.
    const auto farValue = [](const scene::Scene& s) { return s.shape->value(Vec3d(-3.0, 0.0, 0.0)); };
    EXPECT_NEAR(farValue(s1), 3.0 - 0.5, 1e-3);
    EXPECT_NEAR(farValue(s9), 3.8 - 1.0, 1e-3);
    // A scene without keys is not animated, and its start frame is irrelevant.
    EXPECT_FALSE(parseAt(R"({"shape": {"type": "sphere", "radius": 1}})", 3).animated);
}

TEST_F(TestAnimation, BadKeyedValuesAreRefusedWithTheirPath)
{
    const auto sphere = [](const std::string& radius, const std::string& centre = "[0,0,0]") {
        return R"({"shape": {"type": "sphere", "center": )" + centre + R"(, "radius": )" + radius + "}}";
    };
    const std::map<std::string, std::pair<std::string, std::string>> cases = {
        {"unsorted", {sphere(R"({"keys": [[5, 1], [2, 2]]})"), "shape.radius.keys[1][0]: key frames must be strictly increasing"}},
        {"repeated", {sphere(R"({"keys": [[2, 1], [2, 2]]})"), "shape.radius.keys[1][0]: key frames must be strictly increasing"}},
        {"not a pair", {sphere(R"({"keys": [[1, 1, 2]]})"), "shape.radius.keys[0]: must be a [frame, value] pair"}},
        {"not a list", {sphere(R"({"keys": 3})"), "shape.radius.keys: must be a non-empty array"}},
        {"empty", {sphere(R"({"keys": []})"), "shape.radius.keys: must be a non-empty array"}},
        {"frame text", {sphere(R"({"keys": [["a", 1]]})"), "shape.radius.keys[0][0]: must be a frame number"}},
        {"value text", {sphere(R"({"keys": [[1, "big"]]})"), "shape.radius.keys[0][1]: must be a number or an array"}},
        {"vector length", {sphere("1", R"({"keys": [[1, [0,0,0]], [2, [1,0]]]})"), "shape.center.keys[1][1]: has 2 numbers but the first key has 3"}},
        {"vector of 2", {sphere("1", R"({"keys": [[1, [0,0]], [2, [1,0]]]})"), "shape.center: must be an array of 3 numbers"}},
        {"interpolation", {sphere(R"({"keys": [[1, 1]], "interpolation": "cubic"})"), "shape.radius.interpolation: must be one of linear, smooth, step"}},
        {"extra key", {sphere(R"({"keys": [[1, 1]], "easing": 2})"), "shape.radius.easing: unknown key in a keyed value"}},
        {"keyed voxel size", {R"({"voxel_size": {"keys": [[1, 0.1]]}, "shape": {"type": "sphere", "radius": 1}})", "voxel_size: cannot be keyed"}},
        {"frames reversed", {R"({"frames": {"start": 5, "end": 2}, "shape": {"type": "sphere", "radius": 1}})", "frames: start must be <= end"}},
        {"frames fraction", {R"({"frames": {"start": 1.5, "end": 2}, "shape": {"type": "sphere", "radius": 1}})", "frames.start: must be a whole frame number"}},
        {"frames key", {R"({"frames": {"start": 1, "end": 2, "fps": 24}, "shape": {"type": "sphere", "radius": 1}})", "frames.fps: unknown key"}},
        {"negative at start", {sphere(R"({"keys": [[1, -1], [2, 1]]})"), "shape.radius: must be > 0, got -1"}},
    };
    for (const auto& [name, c] : cases) {
        const std::string msg = errorOf(c.first);
        EXPECT_NE(msg.find("anim.json: " + c.second), std::string::npos)
            << name << ": got '" << msg << "'";
    }
}

/// The radius of a rasterized exact sphere centred at the origin: every band voxel's |x| - phi,
/// averaged, and the largest deviation from @a expected (world units).
std::pair<double, double> sphereRadius(const openvdb::FloatGrid& grid, double expected)
{
    double sum = 0.0, worst = 0.0;
    std::size_t n = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        const double r = grid.indexToWorld(it.getCoord()).length() - double(*it);
        sum += r;
        worst = std::max(worst, std::abs(r - expected));
        ++n;
    }
    return {n ? sum / double(n) : 0.0, worst};
}

TEST_F(TestAnimation, KeyedRadiusRasterizesToTheClosedFormAtFiveFrames)
{
    const fs::path dir = fs::temp_directory_path() / ("ivdb-test-anim-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const double dx = 0.02;
    for (const char* mode : {"linear", "smooth", "step"}) {
        const std::string scenePath = (dir / (std::string(mode) + ".json")).string();
        std::ofstream(scenePath) << R"({"voxel_size": 0.02, "shape": {"type": "sphere", "radius":
            {"keys": [[1, 0.3], [11, 0.5], [21, 0.4]], "interpolation": ")" << mode << R"("}}})";
        jobs::SequenceOptions opt;
        opt.base.scene = scenePath;
        opt.frames = scene::parseFrameRange("1-25:3"); // 1, 4, 7, ... 25
        std::map<int, double> radius;
        opt.onFrame = [&](const jobs::FrameReport& f) {
            const int i = f.frame < 11 ? 0 : f.frame < 21 ? 1 : 2;
            const double keyFrames[3] = {1, 11, 21}, keyValues[3] = {0.3, 0.5, 0.4};
            double expected = keyValues[i];
            if (i < 2 && std::string(mode) != "step") {
                double t = (f.frame - keyFrames[i]) / 10.0;
                if (std::string(mode) == "smooth") t = t * t * (3 - 2 * t);
                expected = keyValues[i] + t * (keyValues[i + 1] - keyValues[i]);
            }
            const auto [mean, worst] = sphereRadius(*f.result.surface, expected);
            EXPECT_LT(std::abs(mean - expected), 0.05 * dx) << mode << " frame " << f.frame;
            EXPECT_LT(worst, 0.05 * dx) << mode << " frame " << f.frame;
            EXPECT_EQ(f.result.surface->metaValue<int>("ivdb_frame"), f.frame);
            radius[f.frame] = mean;
        };
        const jobs::SequenceResult r = jobs::rasterizeSequence(opt);
        EXPECT_EQ(r.written, 9u);
        EXPECT_EQ(radius.size(), 9u) << mode;
    }
    fs::remove_all(dir);
}

/// Interrupts once @a after frames have been reported.
class StopAfterFrames final: public util::Interrupter
{
public:
    std::atomic<int> reported{0};
    int after = 0;
    bool wasInterrupted(int) override { return reported.load() >= after; }
};

TEST_F(TestAnimation, AnInterruptionWhileFramesAreInFlightFreesTheirGrids)
{
    // Frames made four at a time, interrupted after the third is reported: the others in flight
    // stop or finish after the pipeline is cancelled. Their grids must still be freed (OpenVDB
    // frees a tree in a parallel loop, which a cancelled context skips: the AddressSanitizer run
    // of this suite finds such a leak), written frames' grids are not kept, and the reports
    // stay in frame order.
    const fs::path dir = fs::temp_directory_path() / ("ivdb-test-stop-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const std::string scenePath = (dir / "grow.json").string();
    std::ofstream(scenePath) << R"({"voxel_size": 0.01, "frames": {"start": 1, "end": 40},
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3], [40, 0.6]]}}})";
    for (const bool toFiles : {false, true}) {
        StopAfterFrames stop;
        stop.after = 3;
        jobs::SequenceOptions opt;
        opt.base.scene = scenePath;
        opt.base.interrupter = &stop;
        if (toFiles) opt.base.output = (dir / "f_##.vdb").string();
        opt.parallelFrames = 4;
        std::vector<int> frames;
        opt.onFrame = [&](const jobs::FrameReport& f) {
            frames.push_back(f.frame);
            EXPECT_EQ(f.result.surface == nullptr, toFiles) << "frame " << f.frame;
            EXPECT_GT(f.result.activeVoxels, 10000u) << "frame " << f.frame;
            ++stop.reported;
        };
        EXPECT_THROW(jobs::rasterizeSequence(opt), openvdb::RuntimeError);
        ASSERT_GE(frames.size(), 3u);
        EXPECT_LT(frames.size(), 40u);
        // The first three in order; after them, frames finished while an earlier one stopped.
        for (std::size_t i = 0; i < frames.size(); ++i) {
            if (i < 3) EXPECT_EQ(frames[i], int(i) + 1);
            else EXPECT_GT(frames[i], frames[i - 1]);
        }
        if (toFiles) {
            std::size_t files = 0;
            for (const auto& e : fs::directory_iterator(dir)) files += e.path().extension() == ".vdb";
            EXPECT_EQ(files, frames.size());
        }
    }
    fs::remove_all(dir);
}

TEST_F(TestAnimation, AFrameSourceMakesOnlyTheFramesItHandsOut)
{
    // SequenceOptions::nextFrame, as ivdb::mpi's ranks share a sequence: only the frames handed
    // out are made, each the same as in the whole sequence, reported as they finish; none makes
    // nothing; a failing frame stops the source being asked.
    const fs::path dir = fs::temp_directory_path() / ("ivdb-test-source-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const std::string scenePath = (dir / "grow.json").string();
    std::ofstream(scenePath) << R"({"voxel_size": 0.02, "frames": {"start": 1, "end": 12},
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3], [12, 0.6]]}}})";
    std::map<int, std::uint64_t> whole;
    jobs::SequenceOptions all;
    all.base.scene = scenePath;
    all.onFrame = [&](const jobs::FrameReport& f) { whole[f.frame] = f.result.activeVoxels; };
    jobs::rasterizeSequence(all);
    ASSERT_EQ(whole.size(), 12u);
    EXPECT_EQ(jobs::sequenceFrames(all).size(), 12u);

    for (const std::vector<std::size_t>& share : {std::vector<std::size_t>{1, 4, 7, 10},
                                                 std::vector<std::size_t>{11, 0},
                                                 std::vector<std::size_t>{}}) {
        // Atomic: the pipeline's input stage runs on different threads, ordered by libtbb,
        // which ThreadSanitizer does not see.
        std::atomic<std::size_t> next{0};
        std::set<int> made;
        jobs::SequenceOptions opt = all;
        opt.parallelFrames = 2;
        opt.nextFrame = [&]() -> std::optional<std::size_t> {
            const std::size_t i = next++;
            if (i >= share.size()) return std::nullopt;
            return share[i];
        };
        opt.framesDone = [] { return std::size_t(0); };
        opt.onFrame = [&](const jobs::FrameReport& f) {
            EXPECT_EQ(f.frame, int(f.index) + 1);
            EXPECT_EQ(f.result.activeVoxels, whole[f.frame]) << "frame " << f.frame;
            EXPECT_GT(f.peakMemory, 0u);
            made.insert(f.frame);
        };
        const jobs::SequenceResult r = jobs::rasterizeSequence(opt);
        std::set<int> want;
        for (std::size_t i : share) want.insert(int(i) + 1);
        EXPECT_EQ(made, want);
        EXPECT_EQ(r.written, share.size());
    }

    // Frame 3 fails (the sphere inside out): the source is not asked for more after it.
    const std::string badPath = (dir / "bad.json").string();
    std::ofstream(badPath) << R"({"voxel_size": 0.02, "frames": {"start": 1, "end": 12},
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3], [3, 2000], [4, 0.3]],
        "interpolation": "step"}}})";
    jobs::SequenceOptions bad;
    bad.base.scene = badPath;
    bad.parallelFrames = 1;
    std::atomic<std::size_t> asked{0};
    bad.nextFrame = [&]() -> std::optional<std::size_t> {
        const std::size_t i = asked++;
        return i < 12 ? std::optional<std::size_t>(i) : std::nullopt;
    };
    EXPECT_THROW(jobs::rasterizeSequence(bad), openvdb::RuntimeError);
    EXPECT_LE(asked.load(), 4u);
    fs::remove_all(dir);
}

} // namespace

// ivdb curvature: mean, Gaussian, principal curvatures or the Laplacian of a level set.
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>

#include <chrono>
#include <cstdio>

namespace ivdb::cli {

namespace {

struct CurvatureOptions
{
    std::string input, output, grid, method = "mean";
    bool withInput = false, quiet = false;
};

const char* convention(const std::string& method)
{
    if (method == "mean") return "mean curvature (k1 + k2) / 2; 1/r on a sphere";
    if (method == "gaussian") return "Gaussian curvature k1 k2; 1/r^2 on a sphere";
    if (method == "principal") return "principal curvatures k1 >= k2; both 1/r on a sphere";
    return "Laplacian of phi (seed eqs. 10-11); 2/r on a sphere's distance field";
}

int runCurvature(const CurvatureOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    io::checkOutputPath(opt.output);
    const auto phi = readLevelSet(opt.input, opt.grid);

    const auto t1 = std::chrono::steady_clock::now();
    openvdb::GridPtrVec computed;
    if (opt.method == "principal") {
        auto [k1, k2] = diff::principalCurvatures(*phi);
        computed = {k1, k2};
    } else {
        const diff::Curvature kind = opt.method == "gaussian" ? diff::Curvature::Gaussian
                                   : opt.method == "laplacian" ? diff::Curvature::Laplacian
                                                               : diff::Curvature::Mean;
        computed = {diff::curvature(*phi, kind)};
    }
    const auto t2 = std::chrono::steady_clock::now();

    openvdb::GridCPtrVec out;
    for (auto& g : computed) {
        stampGrid(*g, opt.input + ":" + phi->getName());
        g->insertMeta("ivdb_curvature", openvdb::StringMetadata(convention(opt.method)));
        out.push_back(g);
    }
    if (opt.withInput) out.push_back(phi);
    writeOutput(opt.output, out);
    const auto t3 = std::chrono::steady_clock::now();
    if (!opt.quiet) {
        std::printf("%s: %s curvature of '%s', %llu active voxels, read %.3f s, compute %.3f s, "
                    "total %.3f s -> %s\n",
                    opt.input.c_str(), opt.method.c_str(), phi->getName().c_str(),
                    (unsigned long long)computed[0]->activeVoxelCount(),
                    std::chrono::duration<double>(t1 - t0).count(),
                    std::chrono::duration<double>(t2 - t1).count(),
                    std::chrono::duration<double>(t3 - t0).count(), opt.output.c_str());
    }
    return 0;
}

} // namespace

void addCurvature(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<CurvatureOptions>();
    CLI::App* cmd = app.add_subcommand("curvature",
        "Curvature of a level set's iso-surfaces on its band, as a FloatGrid 'curvature' "
        "(principal: 'k1' and 'k2'). Conventions, in 1/world units: mean = (k1 + k2) / 2 (1/r on "
        "a sphere, as OpenVDB's meanCurvature); gaussian = k1 k2 (1/r^2); principal = k1 >= k2 "
        "(1/r each); laplacian = the Laplacian of phi, the seed's approximation (2/r on a "
        "sphere's distance field)");
    cmd->add_option("input", opt->input, "Input .vdb file")->required();
    cmd->add_option("-o,--output", opt->output, "Output .vdb file (written atomically)")->required();
    cmd->add_option("--method", opt->method, "mean | gaussian | principal | laplacian")
        ->check(CLI::IsMember({"mean", "gaussian", "principal", "laplacian"}))
        ->capture_default_str();
    cmd->add_option("--grid", opt->grid, "Input grid name (default: the first level set)");
    cmd->add_flag("--with-input", opt->withInput, "Also copy the input grid into the output file");
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runCurvature(*opt); }; });
}

} // namespace ivdb::cli

// SPDX-License-Identifier: Apache-2.0
// The ivdb command line: a thin entry point (see Cli.h).
#include "Cli.h"

namespace ivdb::cli {

int run(int argc, char** argv)
{
    Program ivdb;
    ivdb.name = "ivdb";
    ivdb.description = "ivdb: implicit surfaces to sparse OpenVDB level sets";
    ivdb.commandList = "rasterize, info, gradient, curvature, compare-gradient, check-distances, "
                       "csg, blend, mesh, glyphs, render, convert, plan, bench";
    ivdb.addCommands = [](CLI::App& app, Action& action) {
        addRasterize(app, action);
        addInfo(app, action);
        addGradient(app, action);
        addCurvature(app, action);
        addCompareGradient(app, action);
        addCheckDistances(app, action);
        addCsg(app, action);
        addBlend(app, action);
        addMesh(app, action);
        addGlyphs(app, action);
        addRender(app, action);
        addConvert(app, action);
        addPlan(app, action);
        addBench(app, action);
    };
    return run(argc, argv, ivdb);
}

} // namespace ivdb::cli

int main(int argc, char** argv)
{
    return ivdb::cli::run(argc, argv);
}

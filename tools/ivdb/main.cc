// SPDX-License-Identifier: Apache-2.0
// The ivdb command line: a thin entry point (see Cli.h).
#include "Cli.h"

int main(int argc, char** argv)
{
    return ivdb::cli::run(argc, argv);
}

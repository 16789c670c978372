// The ivdb command line: a thin entry point over the ivdb_cli library.
#include "Cli.h"

int main(int argc, char** argv)
{
    return ivdb::cli::run(argc, argv);
}

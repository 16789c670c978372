// Running the ivdb binary from CLI tests: exit code, stdout and stderr of one run.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <sys/wait.h>

namespace ivdb::test {

struct CliResult
{
    int exitCode = -1; ///< 1000 when the run did not exit normally (a signal, the timeout)
    std::string out, err;
};

inline std::string slurpFile(const std::filesystem::path& p)
{
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Run `ivdb ARGS` in @a dir (killed after @a timeoutSeconds), with stdin from /dev/null.
inline CliResult runIvdb(const std::filesystem::path& dir, const std::vector<std::string>& args,
                         int timeoutSeconds = 120)
{
    std::string cmd = "cd '" + dir.string() + "' && exec timeout -s KILL " +
                      std::to_string(timeoutSeconds) + " '" + std::string(IVDB_BINARY) + "'";
    for (const auto& a : args) cmd += " '" + a + "'";
    const std::filesystem::path out = dir / ".stdout.txt", err = dir / ".stderr.txt";
    cmd += " >'" + out.string() + "' 2>'" + err.string() + "' </dev/null";
    const int status = std::system(cmd.c_str());
    CliResult r;
    r.exitCode = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : 1000;
    r.out = slurpFile(out);
    r.err = slurpFile(err);
    std::filesystem::remove(out);
    std::filesystem::remove(err);
    return r;
}

} // namespace ivdb::test

// SPDX-License-Identifier: Apache-2.0
// Running the ivdb binary from CLI tests: exit code, stdout and stderr of one run.
#pragma once

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include <chrono>
#include <csignal>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace ivdb::test {

#ifdef IVDB_SANITIZED
/// Sanitized binaries run several times slower and reserve terabytes of address space (ASan's
/// shadow), so runs get longer timeouts and no address-space cap.
inline constexpr int kSlowdown = 8;
inline constexpr const char* kAddressCap = "";
#else
inline constexpr int kSlowdown = 1;
/// A 3 GB address-space cap, so a runaway run fails instead of swapping.
inline constexpr const char* kAddressCap = "ulimit -v 3000000 && ";
#endif

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

/// @a s as one single-quoted shell word.
inline std::string shellQuote(const std::string& s)
{
    std::string q = "'";
    for (char c : s) {
        if (c == '\'') q += "'\\''";
        else q += c;
    }
    return q + "'";
}

/// The marks sanitizer reports start with (AddressSanitizer, LeakSanitizer, UBSan's "runtime
/// error:", ThreadSanitizer).
inline const std::vector<std::string>& sanitizerMarks()
{
    static const std::vector<std::string> marks = {"AddressSanitizer", "LeakSanitizer",
        "runtime error:", "UndefinedBehaviorSanitizer", "ThreadSanitizer"};
    return marks;
}

/// Fail the test if a child's stderr holds a sanitizer report: a run that printed one failed,
/// whatever its exit code and message (a report can follow ivdb's own error message).
inline void expectNoSanitizerReport(const std::string& err, const std::string& what = "ivdb run")
{
    for (const auto& mark : sanitizerMarks()) {
        EXPECT_EQ(err.find(mark), std::string::npos)
            << what << ": a sanitizer report (" << mark << ") in its stderr:\n" << err;
    }
}

/// Run `ivdb ARGS` in @a dir (killed after @a timeoutSeconds), with stdin from /dev/null;
/// @a shellPrefix runs first in the same shell (e.g. "ulimit -f 4 && ", or kAddressCap).
/// stdout and stderr go to hidden files in @a dir, removed after the run.
/// "ivdb ARGS" as a user would type it, for messages.
inline std::string commandLine(const std::vector<std::string>& args)
{
    std::string line = "ivdb";
    for (const auto& a : args) line += " " + a;
    return line;
}

inline CliResult runIvdb(const std::filesystem::path& dir, const std::vector<std::string>& args,
                         int timeoutSeconds = 120, const std::string& shellPrefix = "")
{
    std::string cmd = "cd " + shellQuote(dir.string()) + " && " + shellPrefix + "exec timeout -s KILL " +
                      std::to_string(timeoutSeconds * kSlowdown) + " " + shellQuote(IVDB_BINARY);
    for (const auto& a : args) cmd += " " + shellQuote(a);
    const std::filesystem::path out = dir / ".stdout.txt", err = dir / ".stderr.txt";
    cmd += " >" + shellQuote(out.string()) + " 2>" + shellQuote(err.string()) + " </dev/null";
    const int status = std::system(cmd.c_str());
    CliResult r;
    // timeout(1) exits 128 + 9 when it had to kill the run; a signal inside ivdb also shows >= 128.
    r.exitCode = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : 1000;
    r.out = slurpFile(out);
    r.err = slurpFile(err);
    std::filesystem::remove(out);
    std::filesystem::remove(err);
    expectNoSanitizerReport(r.err, commandLine(args));
    return r;
}

/// Start `ivdb ARGS` in @a dir without waiting (stdout and stderr to @a dir/.out.txt and
/// .err.txt, stdin from /dev/null); returns its process id.
inline pid_t spawnIvdb(const std::filesystem::path& dir, const std::vector<std::string>& args,
                       const std::vector<std::pair<std::string, std::string>>& env = {})
{
    std::vector<std::string> argv{IVDB_BINARY};
    argv.insert(argv.end(), args.begin(), args.end());
    const pid_t pid = ::fork();
    if (pid == 0) {
        if (::chdir(dir.c_str()) != 0) ::_exit(127);
        const int in = ::open("/dev/null", O_RDONLY);
        const int out = ::open(".out.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int err = ::open(".err.txt", O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (in < 0 || out < 0 || err < 0) ::_exit(127);
        ::dup2(in, 0);
        ::dup2(out, 1);
        ::dup2(err, 2);
        for (const auto& [name, value] : env) ::setenv(name.c_str(), value.c_str(), 1);
        std::vector<char*> cargs;
        for (auto& a : argv) cargs.push_back(a.data());
        cargs.push_back(nullptr);
        ::execv(cargs[0], cargs.data());
        ::_exit(127);
    }
    return pid;
}

/// Wait up to @a seconds for @a pid; kills it (SIGKILL) on timeout. Returns the exit code, 128 +
/// the signal that ended it, or 1000 on timeout.
inline int waitIvdb(pid_t pid, double seconds)
{
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
        int status = 0;
        const pid_t r = ::waitpid(pid, &status, WNOHANG);
        if (r == pid) {
            if (WIFEXITED(status)) return WEXITSTATUS(status);
            if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
        }
        if (r < 0) return 1000;
        const std::chrono::duration<double> waited = std::chrono::steady_clock::now() - start;
        if (waited.count() > seconds) {
            ::kill(pid, SIGKILL);
            ::waitpid(pid, &status, 0);
            return 1000;
        }
        ::usleep(1000);
    }
}

/// A fixture for runs of the binary in a folder of their own (mDir/run), bounded (60 s, a 3 GB
/// address-space cap), with checks of failed runs: the message, and that nothing was written.
class CliTest: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        mDir = std::filesystem::temp_directory_path() /
               ("ivdb-test-cli-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir / "run");
    }

    void TearDown() override
    {
        std::error_code ec;
        std::filesystem::remove_all(mDir, ec);
    }

    /// Run `ivdb ARGS` in mDir/run; listings of that folder show only what ivdb made.
    CliResult run(const std::vector<std::string>& args) const
    {
        return runIvdb(mDir / "run", args, 60, kAddressCap);
    }

    /// A path inside the working folder of the runs.
    std::string path(const std::string& name) const { return (mDir / "run" / name).string(); }

    static std::string data(const std::string& name)
    {
        return std::string(IVDB_DATA_DIR) + "/" + name;
    }

    void writeText(const std::string& name, const std::string& text) const
    {
        std::ofstream(path(name), std::ios::binary | std::ios::trunc) << text;
    }

    /// Every file and folder below the run folder.
    std::set<std::string> listing() const
    {
        std::set<std::string> names;
        for (const auto& e : std::filesystem::recursive_directory_iterator(mDir / "run")) {
            names.insert(std::filesystem::relative(e.path(), mDir / "run").string());
        }
        return names;
    }

    static void expectMentions(const std::string& text, const std::vector<std::string>& parts,
                               const std::string& what)
    {
        for (const auto& part : parts) {
            EXPECT_NE(text.find(part), std::string::npos)
                << what << ": does not mention '" << part << "':\n" << text;
        }
    }

    /// Check a failed run: non-zero exit (not a signal or the timeout), `ivdb: error: ` first
    /// on stderr naming @a mentions, no summary on stdout.
    static void expectError(const CliResult& r, const std::vector<std::string>& mentions,
                            const std::string& what)
    {
        EXPECT_NE(r.exitCode, 0) << what;
        EXPECT_LT(r.exitCode, 124) << what << ": timed out or killed by a signal";
        EXPECT_EQ(r.err.find("bad_alloc"), std::string::npos)
            << what << ": ran out of memory (3 GB) instead of refusing the input:\n" << r.err;
        EXPECT_EQ(r.err.rfind("ivdb: error: ", 0), 0u) << what << ": stderr is:\n" << r.err;
        expectMentions(r.err, mentions, what);
        EXPECT_EQ(r.out.find("active voxels"), std::string::npos) << what << ": stdout:\n" << r.out;
    }

    /// Run @a args plus `-o OUTPUT` twice: with no output file (none may appear, nor anything
    /// else) and over an existing file (it must stay byte-identical), each a failure naming
    /// @a mentions.
    void expectFails(std::vector<std::string> args, const std::string& output,
                     const std::vector<std::string>& mentions, const std::string& what) const
    {
        args.push_back("-o");
        args.push_back(output);
        {
            SCOPED_TRACE(what + " (no existing output)");
            const std::set<std::string> before = listing();
            expectError(run(args), mentions, what);
            EXPECT_EQ(listing(), before) << what << ": files were created or removed";
        }
        const std::filesystem::path out(path(output));
        // an output that cannot be a file (a missing folder, or a folder itself)
        if (!std::filesystem::is_directory(out.parent_path()) || std::filesystem::exists(out)) return;
        {
            SCOPED_TRACE(what + " (existing output)");
            const std::string old = "an existing output that must not change\n";
            std::ofstream(out, std::ios::binary | std::ios::trunc) << old;
            const std::set<std::string> before = listing();
            expectError(run(args), mentions, what);
            EXPECT_EQ(slurpFile(out), old) << what << ": the existing output changed";
            EXPECT_EQ(listing(), before) << what << ": files were created or removed";
            std::filesystem::remove(out);
        }
    }

    std::filesystem::path mDir;
};

} // namespace ivdb::test

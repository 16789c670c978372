// SPDX-License-Identifier: Apache-2.0
// Robustness of every command against what an unattended pipeline meets: damaged .vdb files
// (truncated, bytes flipped, empty, a folder, not a .vdb), values that are not finite, a full
// disk, signals in the middle of a run, and extreme but valid settings. The rule each time: exit
// 1 with `ivdb: error: <file>: ...` (or 128 + the signal), never a crash or a hang, and no output
// or temporary file left behind.
#include "CliRun.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using ivdb::test::CliResult;
using ivdb::test::kSlowdown;
using ivdb::test::runIvdb;
using ivdb::test::slurpFile;

/// One damaged input: a label for messages and its bytes (or a folder when isFolder).
struct BadInput
{
    std::string label;
    std::string bytes;
    bool isFolder = false;
};

/// The ways a file gets damaged: truncated at @a cuts offsets spread over the file (plus the
/// header's first bytes), @a flips bytes inverted at spread offsets, and the four odd cases.
std::vector<BadInput> damagedVersions(const std::string& good, int cuts, int flips)
{
    std::vector<BadInput> out;
    std::set<size_t> cutAt{1, 4, 8, 12, 16, 17, 24, 60};
    for (int i = 1; i < cuts; ++i) cutAt.insert(good.size() * i / cuts);
    cutAt.insert(good.size() - 1);
    for (size_t n : cutAt) out.push_back({"truncated at " + std::to_string(n), good.substr(0, n)});
    std::set<size_t> flipAt{0, 8, 12, 20, 40, 70};
    for (int i = 1; i < flips; ++i) flipAt.insert(good.size() * i / flips);
    for (size_t n : flipAt) {
        std::string b = good;
        b[n] = char(~b[n]);
        out.push_back({"byte " + std::to_string(n) + " flipped", b});
    }
    out.push_back({"empty", ""});
    out.push_back({"a folder", "", true});
    out.push_back({"text", "this is not a vdb file\n"});
    std::mt19937 rng(7);
    std::string noise(4096, '\0');
    for (char& c : noise) c = char(rng() & 0xff);
    out.push_back({"random bytes", noise});
    out.push_back({"magic then random bytes", good.substr(0, 8) + noise});
    return out;
}

class TestCliRobust: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        mDir = fs::temp_directory_path() /
               ("ivdb-test-cli-robust-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        fs::remove_all(mDir);
        fs::create_directories(mDir);
        write("s.json", R"({"voxel_size": 0.1, "shape": {"type": "sphere", "radius": 1}})");
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    void write(const std::string& name, const std::string& bytes) const
    {
        std::ofstream(mDir / name, std::ios::binary | std::ios::trunc) << bytes;
    }

    CliResult run(const std::vector<std::string>& args, const std::string& prefix = "") const
    {
        return runIvdb(mDir, args, 60, prefix);
    }

    /// Every file in mDir (hidden ones too) that is not in @a inputs.
    std::vector<std::string> leftovers(const std::set<std::string>& inputs) const
    {
        std::vector<std::string> out;
        for (const auto& e : fs::directory_iterator(mDir)) {
            const std::string name = e.path().filename().string();
            if (!inputs.count(name)) out.push_back(name);
        }
        return out;
    }

    std::set<std::string> names() const
    {
        std::set<std::string> out;
        for (const auto& e : fs::directory_iterator(mDir)) out.insert(e.path().filename().string());
        return out;
    }

    /// Run @a args (with "BAD" standing for the damaged file) on every damaged version of
    /// @a good; returns how many runs refused the file (the rest accepted a file whose damage
    /// left it valid, which only a flipped byte may do).
    int sweep(const std::string& good, const std::vector<std::string>& args, int cuts, int flips)
    {
        const std::set<std::string> before = names();
        int refused = 0, runs = 0, crashed = 0;
        for (const BadInput& bad : damagedVersions(good, cuts, flips)) {
            const std::string name = "bad.vdb";
            if (bad.isFolder) fs::create_directory(mDir / name);
            else write(name, bad.bytes);
            std::vector<std::string> a = args;
            for (auto& s : a) if (s == "BAD") s = name;
            const CliResult r = run(a);
            ++runs;
            const std::string what = "ivdb " + args.front() + " on a file " + bad.label;
            EXPECT_LT(r.exitCode, 128) << what << ": killed by a signal or timed out\n" << r.err;
            if (r.exitCode >= 128) ++crashed;
            std::set<std::string> expected = before;
            expected.insert(name);
            if (r.exitCode != 0) {
                ++refused;
                EXPECT_EQ(r.exitCode, 1) << what << "\n" << r.err;
                EXPECT_EQ(r.err.rfind("ivdb: error: ", 0), 0u) << what << ": " << r.err;
                EXPECT_NE(r.err.find(name), std::string::npos) << what << ": the message does "
                                                                  "not name the file: " << r.err;
                EXPECT_EQ(leftovers(expected), std::vector<std::string>{}) << what;
            } else {
                EXPECT_NE(bad.label.find("flipped"), std::string::npos)
                    << what << ": accepted\n" << r.out;
            }
            for (const auto& f : leftovers(expected)) fs::remove_all(mDir / f);
            fs::remove_all(mDir / name);
        }
        std::cout << "[ robust ] ivdb " << args.front() << ": " << runs << " damaged inputs, "
                  << refused << " refused with an error, " << runs - refused
                  << " accepted (a flipped byte left a valid file), " << crashed
                  << " killed by a signal or timed out" << std::endl;
        RecordProperty("damaged_inputs", runs);
        RecordProperty("refused", refused);
        return refused;
    }

    std::string makeSphere(const std::string& name = "good.vdb") const
    {
        const CliResult r = run({"rasterize", "s.json", "-o", name, "-q"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        return slurpFile(mDir / name);
    }

    fs::path mDir;
};

TEST_F(TestCliRobust, DamagedFilesInInfoAndTheDifferentialCommands)
{
    const std::string good = makeSphere();
    ASSERT_GT(good.size(), 1000u);
    EXPECT_GT(sweep(good, {"info", "BAD"}, 16, 12), 20);
    EXPECT_GT(sweep(good, {"gradient", "BAD", "-o", "out.vdb", "-q"}, 16, 12), 20);
    EXPECT_GT(sweep(good, {"curvature", "BAD", "-o", "out.vdb", "-q"}, 12, 8), 20);
}

TEST_F(TestCliRobust, DamagedFilesInCsgAndBlend)
{
    const std::string good = makeSphere();
    EXPECT_GT(sweep(good, {"csg", "union", "BAD", "good.vdb", "-o", "out.vdb", "-q"}, 16, 12), 20);
    EXPECT_GT(sweep(good, {"blend", "union", "good.vdb", "BAD", "-p", "10", "-o", "out.vdb", "-q"},
                    12, 8), 20);
}

TEST_F(TestCliRobust, DamagedFilesInMeshRenderAndGlyphs)
{
    const std::string good = makeSphere();
    EXPECT_GT(sweep(good, {"mesh", "BAD", "-o", "out.obj", "-q"}, 12, 8), 20);
    EXPECT_GT(sweep(good, {"render", "BAD", "-o", "out.png", "--size", "32x24", "-q"}, 12, 8), 20);
    EXPECT_GT(sweep(good, {"mesh", "good.vdb", "-o", "out.ply", "--color-by", "BAD", "-q"}, 12, 8),
              20);
    ASSERT_EQ(run({"gradient", "good.vdb", "-o", "grad.vdb", "-q"}).exitCode, 0);
    EXPECT_GT(sweep(slurpFile(mDir / "grad.vdb"), {"glyphs", "BAD", "-o", "out.obj", "-q"}, 12, 8),
              20);
}

// NaN, infinity and a broken transform written by another tool: refused before use.
TEST_F(TestCliRobust, ValuesThatAreNotFiniteAreRefused)
{
    makeSphere();
    auto load = [&]() {
        openvdb::io::File f((mDir / "good.vdb").string());
        f.open();
        auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(f.readGrid("surface"));
        f.close();
        return g;
    };
    auto save = [&](const std::string& name, openvdb::FloatGrid::Ptr g) {
        openvdb::io::File((mDir / name).string()).write({g});
    };
    {
        auto g = load();
        g->tree().setValueOn(openvdb::Coord(10, 0, 0), std::nanf(""));
        save("nan.vdb", g);
    }
    {
        auto g = load();
        g->tree().setValueOff(openvdb::Coord(500, 0, 0), INFINITY);
        save("inf.vdb", g);
    }
    {
        auto g = load();
        g->setTransform(openvdb::math::Transform::createLinearTransform(std::nan("")));
        save("nan_voxel.vdb", g);
    }
    {
        auto g = load();
        g->tree().root().setBackground(-0.3f, /*updateChildNodes=*/false);
        save("negative_background.vdb", g);
    }
    const std::set<std::string> before = names();
    for (const std::string bad : {"nan.vdb", "inf.vdb", "nan_voxel.vdb", "negative_background.vdb"}) {
        const std::vector<std::vector<std::string>> commands{
            {"info", bad},
            {"gradient", bad, "-o", "out.vdb"},
            {"curvature", bad, "-o", "out.vdb"},
            {"csg", "union", "good.vdb", bad, "-o", "out.vdb"},
            {"blend", "union", bad, "good.vdb", "-p", "10", "-o", "out.vdb"},
            {"mesh", bad, "-o", "out.obj"},
            {"render", bad, "-o", "out.png", "--size", "32x24"},
            {"render", "good.vdb", "-o", "out.png", "--size", "32x24", "--color-by", bad},
        };
        for (const auto& args : commands) {
            const CliResult r = run(args);
            const std::string what = "ivdb " + args.front() + " on " + bad;
            EXPECT_EQ(r.exitCode, 1) << what << "\n" << r.err;
            EXPECT_NE(r.err.find("ivdb: error: " + bad + ": grid 'surface'"), std::string::npos)
                << what << ": " << r.err;
            EXPECT_EQ(leftovers(before), std::vector<std::string>{}) << what;
        }
    }
    EXPECT_NE(run({"info", "nan.vdb"}).err.find("not finite"), std::string::npos);
    EXPECT_NE(run({"info", "nan_voxel.vdb"}).err.find("invalid transform"), std::string::npos);
    EXPECT_NE(run({"info", "negative_background.vdb"}).err.find("background"), std::string::npos);
}

// A full disk as a file-size limit: the write fails with EFBIG part way.
TEST_F(TestCliRobust, FullDiskGivesAClearErrorAndKeepsTheOldOutput)
{
    write("fine.json", R"({"voxel_size": 0.02, "shape": {"type": "sphere", "radius": 1}})");
    write("out.vdb", "old output");
    const std::set<std::string> before = names();
    for (const auto& args : std::vector<std::vector<std::string>>{
             {"rasterize", "fine.json", "-o", "out.vdb"},
             {"rasterize", "fine.json", "-o", "out.obj"},
         }) {
        // ulimit -f counts 1 kB blocks: 16 kB is far less than either output.
        const CliResult r = run(args, "ulimit -f 16 && ");
        EXPECT_EQ(r.exitCode, 1) << r.err;
        EXPECT_NE(r.err.find("ivdb: error: " + args[3]), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("is the disk full?"), std::string::npos) << r.err;
        EXPECT_EQ(leftovers(before), std::vector<std::string>{});
        EXPECT_EQ(slurpFile(mDir / "out.vdb"), "old output");
    }
    {
        makeSphere("big.vdb");
        const std::set<std::string> withBig = names();
        for (const auto& args : std::vector<std::vector<std::string>>{
                 {"mesh", "big.vdb", "-o", "out.obj"},
                 {"gradient", "big.vdb", "-o", "out.vdb"},
                 {"render", "big.vdb", "-o", "out.png"},
             }) {
            const CliResult r = run(args, "ulimit -f 1 && ");
            EXPECT_EQ(r.exitCode, 1) << args.front() << ": " << r.err;
            EXPECT_NE(r.err.find("is the disk full?"), std::string::npos) << r.err;
            EXPECT_EQ(leftovers(withBig), std::vector<std::string>{}) << args.front();
        }
    }
    // A device as the output is refused up front, /dev/full included.
    const CliResult dev = run({"rasterize", "s.json", "-o", "/dev/full"});
    EXPECT_EQ(dev.exitCode, 1);
    EXPECT_NE(dev.err.find("not a regular file"), std::string::npos) << dev.err;
}

/// The shell words that preload tests/faults/WriteFaults.cc into a run with IVDB_FAULT=@a fault.
std::string withFault(const std::string& fault)
{
    return "export LD_PRELOAD=" + ivdb::test::shellQuote(IVDB_WRITE_FAULTS) + " IVDB_FAULT=" +
           ivdb::test::shellQuote(fault) + " && ";
}

// Write failures, injected (tests/faults/WriteFaults.cc) so that they happen on every machine:
// a full disk (ENOSPC), a failing one (EIO), a write that takes nothing, a failed fsync. Each
// command that writes names its output and the cause, exits 1, leaves no file behind and the
// old output untouched. Short writes are legal and give the same file as a normal run.
TEST_F(TestCliRobust, InjectedWriteFailuresKeepTheOldOutput)
{
    write("fine.json", R"({"voxel_size": 0.02, "shape": {"type": "sphere", "radius": 1}})");
    makeSphere("big.vdb");
    const std::vector<std::vector<std::string>> commands{
        {"rasterize", "fine.json", "-o", "out.vdb"},
        {"rasterize", "fine.json", "-o", "out.obj"},
        {"gradient", "big.vdb", "-o", "out.vdb"},
        {"csg", "union", "big.vdb", "big.vdb", "-o", "out.vdb"},
        {"mesh", "big.vdb", "-o", "out.ply"},
        {"render", "big.vdb", "-o", "out.png"},
        {"convert", "big.vdb", "-o", "out.nvdb"},
    };
    const std::vector<std::pair<std::string, std::string>> faults{
        {"enospc:4096", "cannot write: No space left on device (is the disk full?)"},
        {"eio:4096", "cannot write: Input/output error (is the disk full?)"},
        {"zero:4096", "cannot write: No space left on device (is the disk full?)"},
        {"fsync-eio", "cannot sync the written file: Input/output error"},
    };
    for (const auto& args : commands) {
        const std::string output = args[args.size() - 1];
        write(output, "old output");
        const std::set<std::string> before = names();
        for (const auto& [fault, says] : faults) {
            const CliResult r = run(args, withFault(fault));
            const std::string what = args[0] + " -o " + output + " with " + fault;
            EXPECT_EQ(r.exitCode, 1) << what << ": " << r.err;
            EXPECT_NE(r.err.find("ivdb: error: " + output + ": " + says), std::string::npos)
                << what << ": " << r.err;
            EXPECT_EQ(leftovers(before), std::vector<std::string>{}) << what;
            EXPECT_EQ(slurpFile(mDir / output), "old output") << what;
        }
        // Writes of at most 1000 bytes each: the same file as without the fault.
        fs::remove(mDir / output);
        ASSERT_EQ(run(args).exitCode, 0) << args[0];
        const std::string plain = slurpFile(mDir / output);
        fs::remove(mDir / output);
        const CliResult r = run(args, withFault("short:1000"));
        ASSERT_EQ(r.exitCode, 0) << args[0] << " with short writes: " << r.err;
        const std::string shortWritten = slurpFile(mDir / output);
        ASSERT_EQ(shortWritten.size(), plain.size()) << args[0];
        // A .vdb (whatever its name) holds the file's unique id (36 bytes from offset 21): the
        // rest must match.
        const auto withoutId = [&](const std::string& b) {
            return b.size() > 57 && b.compare(0, 4, " BDV") == 0 ? b.substr(0, 21) + b.substr(57) : b;
        };
        EXPECT_TRUE(withoutId(shortWritten) == withoutId(plain)) << args[0] << " -o " << output;
    }
}

/// CPU seconds (user + system) process @a pid has used so far; 0 if it cannot be read.
double cpuSeconds(pid_t pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
    std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t close = stat.rfind(')'); // the command name may hold spaces
    if (close == std::string::npos) return 0.0;
    std::istringstream fields(stat.substr(close + 2));
    std::string f;
    unsigned long long utime = 0, stime = 0;
    for (int i = 3; i <= 15 && fields >> f; ++i) {
        if (i == 14) utime = std::stoull(f);
        if (i == 15) stime = std::stoull(f);
    }
    return double(utime + stime) / double(::sysconf(_SC_CLK_TCK));
}

// Ctrl-C during a long computation stops it through the interrupter; a signal while the output
// is being written removes the temporary file; SIGKILL there leaves the old output whole.
TEST_F(TestCliRobust, SignalsStopRunsAndLeaveNoPartialOutput)
{
    using ivdb::test::spawnIvdb;
    using ivdb::test::waitIvdb;
    // Dense sampling of 800^3 voxels: seconds of work, polled by the interrupter.
    write("dense.json", R"({"voxel_size": 0.0025, "shape": {"type": "sphere", "radius": 1}})");
    std::set<std::string> before = names();
    {
        const pid_t pid = spawnIvdb(mDir, {"rasterize", "dense.json", "--sampling", "dense", "-o", "out.vdb"});
        // Signal once it has spent half a second of CPU time: past reading the scene (a few
        // milliseconds), inside seconds of sampling, however slow or busy the machine is.
        for (int i = 0; i < 20000 * kSlowdown && cpuSeconds(pid) < 0.5; ++i) ::usleep(1000);
        ASSERT_GE(cpuSeconds(pid), 0.5) << "the run did not start";
        ASSERT_EQ(::kill(pid, SIGINT), 0);
        const auto t0 = std::chrono::steady_clock::now();
        const int code = waitIvdb(pid, 20.0 * kSlowdown);
        const std::chrono::duration<double> took = std::chrono::steady_clock::now() - t0;
        const std::string err = slurpFile(mDir / ".err.txt");
        ivdb::test::expectNoSanitizerReport(err, "SIGINT during dense sampling");
        EXPECT_EQ(code, 130) << err;
        EXPECT_NE(err.find("interrupted"), std::string::npos) << err;
        std::cout << "[ robust ] SIGINT during dense sampling: exit " << code << " after "
                  << took.count() << " s" << std::endl;
        // docs/reliability.md: within 1 s (the interrupter is polled by every parallel task).
        EXPECT_LT(took.count(), 1.0 * kSlowdown);
        before.insert(".err.txt");
        before.insert(".out.txt");
        EXPECT_EQ(leftovers(before), std::vector<std::string>{});
    }
    // A large gradient output: signal as soon as its temporary file appears.
    write("big.json", R"({"voxel_size": 0.004, "shape": {"type": "sphere", "radius": 1}})");
    ASSERT_EQ(run({"rasterize", "big.json", "-o", "big.vdb", "-q"}).exitCode, 0);
    before = names();
    // The run stops in its first write of the output (tests/faults/WriteFaults.cc, "pause") and
    // marks it: the signal certainly comes while the temporary file is being written.
    const fs::path mark = fs::temp_directory_path() / ("ivdb-write-mark-" + std::to_string(::getpid()));
    auto signalDuringWrite = [&](int sig) {
        fs::remove(mark);
        const pid_t pid = spawnIvdb(mDir, {"gradient", "big.vdb", "-o", "out.vdb"},
            {{"LD_PRELOAD", IVDB_WRITE_FAULTS}, {"IVDB_FAULT", "pause"}, {"IVDB_FAULT_MARK", mark.string()}});
        for (int i = 0; i < 60000 * kSlowdown && !fs::exists(mark); ++i) ::usleep(1000);
        EXPECT_TRUE(fs::exists(mark)) << "the run never wrote its output";
        bool temporary = false;
        for (const auto& e : fs::directory_iterator(mDir)) {
            temporary = temporary || e.path().filename().string().rfind(".out.vdb.tmp-", 0) == 0;
        }
        EXPECT_TRUE(temporary) << "no temporary file while writing";
        ::kill(pid, sig);
        const int code = waitIvdb(pid, 20.0 * kSlowdown);
        ivdb::test::expectNoSanitizerReport(slurpFile(mDir / ".err.txt"), "signal during a write");
        return code;
    };
    EXPECT_EQ(signalDuringWrite(SIGTERM), 128 + SIGTERM) << slurpFile(mDir / ".err.txt");
    EXPECT_EQ(leftovers(before), std::vector<std::string>{});
    EXPECT_EQ(signalDuringWrite(SIGINT), 128 + SIGINT) << slurpFile(mDir / ".err.txt");
    EXPECT_EQ(leftovers(before), std::vector<std::string>{});

    write("out.vdb", "old output");
    EXPECT_EQ(signalDuringWrite(SIGKILL), 128 + SIGKILL);
    EXPECT_EQ(slurpFile(mDir / "out.vdb"), "old output");
    fs::remove(mark);
    // The next run replaces it with the complete file.
    ASSERT_EQ(run({"gradient", "big.vdb", "-o", "out.vdb", "-q"}).exitCode, 0);
    openvdb::io::File f((mDir / "out.vdb").string());
    f.open();
    EXPECT_TRUE(f.readGrid("gradient")->activeVoxelCount() > 100000);
}

/// The environment of running process @a pid, one "NAME=value" per entry.
std::vector<std::string> environmentOf(pid_t pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/environ");
    std::vector<std::string> out;
    std::string entry;
    while (std::getline(in, entry, '\0')) out.push_back(entry);
    return out;
}

/// A /proc/PID/smaps_rollup field in kB (AnonHugePages, say); -1 if it cannot be read.
long smapsKb(pid_t pid, const std::string& field)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/smaps_rollup");
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
    }
    return -1;
}

// docs/performance.md#huge-pages: ivdb (its launcher, bin/ivdb) runs the program (same pid) with
// glibc's malloc asking for transparent huge pages where the kernel's THP mode is "madvise", its
// heaps growing in 64 MiB steps and keeping what they free; IVDB_HUGEPAGES=0 keeps it from doing
// so, and the user's own GLIBC_TUNABLES are kept. Checked on the running process, held in its
// output's write (tests/faults/WriteFaults.cc, "pause").
TEST_F(TestCliRobust, RunsWithHugePages)
{
    using ivdb::test::spawnIvdb;
    using ivdb::test::waitIvdb;
    std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string modes;
    std::getline(thp, modes);
    const bool madvise = modes.find("[madvise]") != std::string::npos;
    write("big.json", R"({"voxel_size": 0.004, "shape": {"type": "sphere", "radius": 1}})");
    ASSERT_EQ(run({"rasterize", "big.json", "-o", "big.vdb", "-q"}).exitCode, 0);
    const fs::path mark = fs::temp_directory_path() / ("ivdb-write-mark-" + std::to_string(::getpid()));
    struct Case { std::vector<std::pair<std::string, std::string>> env; std::string expect; };
    const std::string ours = "glibc.malloc.hugetlb=1:glibc.malloc.top_pad=67108864:"
                             "glibc.malloc.trim_threshold=1073741824:"
                             "glibc.malloc.mmap_threshold=33554432";
    const std::vector<Case> cases{
        {{}, madvise ? "GLIBC_TUNABLES=" + ours : ""},
        {{{"IVDB_HUGEPAGES", "0"}}, ""},
        {{{"GLIBC_TUNABLES", "glibc.malloc.check=0"}},
         madvise ? "GLIBC_TUNABLES=glibc.malloc.check=0:" + ours
                 : "GLIBC_TUNABLES=glibc.malloc.check=0"},
        // A tunable of the user's keeps its value; the others are added.
        {{{"GLIBC_TUNABLES", "glibc.malloc.top_pad=1048576"}},
         madvise ? "GLIBC_TUNABLES=glibc.malloc.top_pad=1048576:glibc.malloc.hugetlb=1:"
                   "glibc.malloc.trim_threshold=1073741824:glibc.malloc.mmap_threshold=33554432"
                 : "GLIBC_TUNABLES=glibc.malloc.top_pad=1048576"},
        {{{"GLIBC_TUNABLES", "glibc.malloc.hugetlb=0"}}, "GLIBC_TUNABLES=glibc.malloc.hugetlb=0"}};
    for (const Case& c : cases) {
        fs::remove(mark);
        auto env = c.env;
        env.push_back({"LD_PRELOAD", IVDB_WRITE_FAULTS});
        env.push_back({"IVDB_FAULT", "pause"});
        env.push_back({"IVDB_FAULT_MARK", mark.string()});
        std::string what = "env";
        for (const auto& [name, value] : c.env) what += " " + name + "=" + value;
        const pid_t pid = spawnIvdb(mDir, {"gradient", "big.vdb", "-o", "out.vdb"}, env);
        for (int i = 0; i < 60000 * kSlowdown && !fs::exists(mark); ++i) ::usleep(1000);
        ASSERT_TRUE(fs::exists(mark)) << what << ": the run never wrote its output";
        // glibc before 2.39 ends each tunable's value in place with a NUL as it parses
        // GLIBC_TUNABLES, so /proc shows "a=1:b=2" as the entries "GLIBC_TUNABLES=a=1" and
        // "b=2": the entries that follow it and name a glibc tunable are joined back.
        std::string tunables;
        const std::vector<std::string> environ = environmentOf(pid);
        for (std::size_t i = 0; i < environ.size(); ++i) {
            if (environ[i].rfind("GLIBC_TUNABLES=", 0) != 0) continue;
            tunables = environ[i];
            while (i + 1 < environ.size() && environ[i + 1].rfind("glibc.", 0) == 0) {
                tunables += ":" + environ[++i];
            }
        }
        EXPECT_EQ(tunables, c.expect) << what;
#ifndef IVDB_SANITIZED // the sanitizers' allocators do not read glibc's tunables
        // The grid (about 60 MB) sits in huge pages where malloc asked for them, and in none
        // where it did not.
        const long huge = smapsKb(pid, "AnonHugePages");
        if (c.expect == "GLIBC_TUNABLES=" + ours) {
            // Nearly all of it: with hugetlb=1 alone, a quarter or more stayed in 4 KiB pages
            // (the heaps grown in small steps, and trimmed).
            EXPECT_GE(double(huge), 0.85 * double(smapsKb(pid, "Anonymous"))) << what;
        } else if (c.expect.find("hugetlb=1") != std::string::npos) {
            EXPECT_GE(huge, 2048) << what;
        } else if (madvise) {
            EXPECT_EQ(huge, 0) << what;
        }
#endif
        ::kill(pid, SIGKILL);
        EXPECT_EQ(waitIvdb(pid, 20.0 * kSlowdown), 128 + SIGKILL) << what;
    }
    fs::remove(mark);
}

// The launcher (bin/ivdb) runs ../libexec/ivdb/ivdb; moved away from it, it says so and where.
TEST_F(TestCliRobust, LauncherWithoutItsProgramSaysWhere)
{
    fs::create_directories(mDir / "bin");
    fs::copy_file(IVDB_BINARY, mDir / "bin" / "ivdb");
    const std::string cmd = "cd " + mDir.string() + " && bin/ivdb --version >out.txt 2>err.txt";
    const int status = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 127);
    const std::string err = slurpFile(mDir / "err.txt");
    EXPECT_NE(err.find("ivdb: error: cannot run the ivdb program " +
                       (mDir / "bin" / ".." / "libexec" / "ivdb" / "ivdb").string()),
              std::string::npos) << err;
    EXPECT_NE(err.find("No such file or directory"), std::string::npos) << err;
    EXPECT_EQ(slurpFile(mDir / "out.txt"), "");
}

// Degenerate quadrics and shapes with no surface in the bounds: a clear error, no empty grid.
TEST_F(TestCliRobust, DegenerateShapesAreRefused)
{
    const std::string bounds = R"("bounds": {"min": [-1, -1, -1], "max": [1, 1, 1]}, )";
    const std::vector<std::pair<std::string, std::string>> cases{
        {R"({"type": "quadric", "matrix": [[0,0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,0]]})", "all zero"},
        {R"({"type": "quadric", "matrix": [[0,0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,1]]})", "constant"},
        // a point: x^2 + y^2 + z^2 = 0
        {R"({"type": "quadric", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,0]]})", "no voxels"},
        // a double plane: x^2 = 0, never negative
        {R"({"type": "quadric", "matrix": [[1,0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,0]]})", "no voxels"},
        // an empty ellipsoid: x^2 + y^2 + z^2 + 1 = 0
        {R"({"type": "quadric", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]})", "no voxels"},
        // a sphere outside the bounds
        {R"({"type": "sphere", "center": [5, 5, 5], "radius": 1})", "no voxels"},
    };
    const std::set<std::string> before = names();
    for (const auto& [shape, expected] : cases) {
        write("bad.json", R"({"voxel_size": 0.05, )" + bounds + R"("shape": )" + shape + "}");
        const CliResult r = run({"rasterize", "bad.json", "-o", "out.vdb"});
        EXPECT_EQ(r.exitCode, 1) << shape << "\n" << r.err;
        EXPECT_NE(r.err.find("ivdb: error: bad.json"), std::string::npos) << shape << ": " << r.err;
        EXPECT_NE(r.err.find(expected), std::string::npos) << shape << ": " << r.err;
        std::set<std::string> expectedNames = before;
        expectedNames.insert("bad.json");
        EXPECT_EQ(leftovers(expectedNames), std::vector<std::string>{}) << shape;
    }
}

// Extreme but valid settings work and give the closed-form band.
TEST_F(TestCliRobust, ExtremeButValidSettingsWork)
{
    auto activeVoxels = [&](const std::string& file) -> double {
        const CliResult r = run({"info", "--json", file});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        return nlohmann::json::parse(r.out)["grids"][0]["active_voxels"].get<double>();
    };
    // |d| < w dx around a sphere: the shell's volume in voxels.
    auto shell = [](double r, double dx, double w) {
        const double a = r / dx + w, b = r / dx - w;
        return 4.0 / 3.0 * M_PI * (a * a * a - b * b * b);
    };
    write("tiny.json", R"({"voxel_size": 1e-4, "shape": {"type": "sphere", "radius": 0.005}})");
    ASSERT_EQ(run({"rasterize", "tiny.json", "-o", "tiny.vdb", "-q"}).exitCode, 0);
    EXPECT_NEAR(activeVoxels("tiny.vdb") / shell(0.005, 1e-4, 3), 1.0, 0.02);
    for (double w : {1.0, 20.0}) {
        const std::string out = "w" + std::to_string(int(w)) + ".vdb";
        const CliResult r = run({"rasterize", "s.json", "--voxel-size", "0.02", "--half-width",
                                 std::to_string(w), "-o", out, "-q"});
        ASSERT_EQ(r.exitCode, 0) << r.err;
        EXPECT_NEAR(activeVoxels(out) / shell(1.0, 0.02, w), 1.0, 0.03) << "half width " << w;
        EXPECT_EQ(run({"gradient", out, "-o", "g.vdb", "-q"}).exitCode, 0) << "half width " << w;
        EXPECT_EQ(run({"curvature", out, "-o", "c.vdb", "-q"}).exitCode, 0) << "half width " << w;
        EXPECT_EQ(run({"mesh", out, "-o", "m.obj", "-q"}).exitCode, 0) << "half width " << w;
    }
    // p = 1000 in a scene and on grids: the sharp union, within a voxel.
    write("a.json", R"({"voxel_size": 0.05, "shape": {"type": "sphere", "center": [-0.5, 0, 0], "radius": 1}})");
    write("b.json", R"({"voxel_size": 0.05, "shape": {"type": "sphere", "center": [0.5, 0, 0], "radius": 1}})");
    write("p1000.json", R"({"voxel_size": 0.05, "shape": {"type": "blend", "op": "union", "p": 1000,
        "children": [{"type": "sphere", "center": [-0.5, 0, 0], "radius": 1},
                     {"type": "sphere", "center": [0.5, 0, 0], "radius": 1}]}})");
    for (const char* s : {"a", "b", "p1000"}) {
        ASSERT_EQ(run({"rasterize", std::string(s) + ".json", "-o", std::string(s) + ".vdb", "-q"}).exitCode, 0);
    }
    ASSERT_EQ(run({"csg", "union", "a.vdb", "b.vdb", "-o", "sharp.vdb", "-q"}).exitCode, 0);
    const CliResult blend = run({"blend", "union", "a.vdb", "b.vdb", "-p", "1000", "-o", "grid1000.vdb", "-q"});
    ASSERT_EQ(blend.exitCode, 0) << blend.err;
    const double sharp = activeVoxels("sharp.vdb");
    EXPECT_NEAR(activeVoxels("p1000.vdb") / sharp, 1.0, 0.01);
    EXPECT_NEAR(activeVoxels("grid1000.vdb") / sharp, 1.0, 0.01);
}

} // namespace

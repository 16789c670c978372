// SPDX-License-Identifier: Apache-2.0
// ivdb rasterize on keyed scenes: sequences with a frame step, --resume, Ctrl-C between and
// during frames, and every bad keyed value or frame option refused with nothing written.
#include "CliRun.h"

#include <ivdb/io/VdbFile.h>

#include <csignal>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace ivdb::test {
namespace {

namespace fs = std::filesystem;

// A sphere whose radius grows from 0.3 to 0.6 over frames 1-48.
const char* kGrowing = R"({"voxel_size": 0.02, "frames": {"start": 1, "end": 48},
    "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3], [48, 0.6]]}}})";

/// True while signal @a sig is pending for process @a pid (ShdPnd in /proc/PID/status).
bool signalPending(pid_t pid, int sig)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("ShdPnd:", 0) == 0) return (std::stoull(line.substr(7), nullptr, 16) >> (sig - 1)) & 1u;
    }
    return false;
}

class TestCliAnimation: public CliTest
{
protected:
    /// The `ivdb_frame` of the file's surface grid; -1 if it does not read whole.
    int frameOf(const std::string& name) const
    {
        try {
            for (const auto& g : io::readVdb(path(name))) {
                if (g->getName() == "surface") return g->metaValue<int>("ivdb_frame");
            }
        } catch (const openvdb::Exception&) {
        }
        return -1;
    }
};

TEST_F(TestCliAnimation, FramesWithAStepWriteOneFilePerFrame)
{
    writeText("grow.json", kGrowing);
    fs::create_directories(path("seq"));
    const CliResult r = run({"rasterize", "grow.json", "--frames", "2-10:4", "-o", "seq/g_###.vdb"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(listing(), (std::set<std::string>{"grow.json", "seq", "seq/g_002.vdb",
                                                "seq/g_006.vdb", "seq/g_010.vdb"}));
    for (int f : {2, 6, 10}) {
        char name[32];
        std::snprintf(name, sizeof name, "seq/g_%03d.vdb", f);
        EXPECT_EQ(frameOf(name), f);
        expectMentions(r.out, {"grow.json frame " + std::to_string(f) + ": ", std::string("-> ") + name}, "summary");
    }
    expectMentions(r.out, {"3 frames written, 0 skipped"}, "summary");
    // The scene's own range when --frames is not given, and one frame without a #.
    ASSERT_EQ(run({"rasterize", "grow.json", "-o", "all_##.vdb", "-q"}).exitCode, 0);
    EXPECT_EQ(frameOf("all_01.vdb"), 1);
    EXPECT_EQ(frameOf("all_48.vdb"), 48);
    EXPECT_TRUE(fs::exists(path("all_25.vdb")));
    ASSERT_EQ(run({"rasterize", "grow.json", "--frames", "7", "-o", "seven.vdb", "-q"}).exitCode, 0);
    EXPECT_EQ(frameOf("seven.vdb"), 7);
}

TEST_F(TestCliAnimation, ResumeSkipsWholeFramesAndRedoesBrokenOnes)
{
    writeText("grow.json", kGrowing);
    ASSERT_EQ(run({"rasterize", "grow.json", "--frames", "1-3", "-o", "f_#.vdb", "-q"}).exitCode, 0);
    const std::string first = slurpFile(path("f_1.vdb"));
    const std::string third = slurpFile(path("f_3.vdb"));
    // Frame 2 cut short, as a killed copy would leave it.
    const std::string second = slurpFile(path("f_2.vdb"));
    std::ofstream(path("f_2.vdb"), std::ios::binary | std::ios::trunc) << second.substr(0, second.size() / 2);
    ASSERT_EQ(frameOf("f_2.vdb"), -1);
    fs::last_write_time(path("f_1.vdb"), fs::file_time_type::clock::now() - std::chrono::hours(1));
    const auto stamp = fs::last_write_time(path("f_1.vdb"));

    const CliResult r = run({"rasterize", "grow.json", "--frames", "1-4", "--resume", "-o", "f_#.vdb"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"frame 1: already written, skipped", "frame 3: already written, skipped",
                           "2 frames written, 2 skipped"}, "resume");
    EXPECT_EQ(r.out.find("frame 2: already written"), std::string::npos) << r.out;
    EXPECT_EQ(fs::last_write_time(path("f_1.vdb")), stamp);
    EXPECT_EQ(slurpFile(path("f_1.vdb")), first);
    EXPECT_EQ(slurpFile(path("f_3.vdb")), third);
    EXPECT_EQ(frameOf("f_2.vdb"), 2);
    EXPECT_EQ(frameOf("f_4.vdb"), 4);
}

// Ctrl-C once some frames are written: those stay whole, the frame being made is not written,
// no temporary file is left, and the message says how many frames were written.
TEST_F(TestCliAnimation, InterruptLeavesWholeFramesOnly)
{
    // About a million voxels a frame: tens of milliseconds each, hundreds of frames.
    writeText("big.json", R"({"voxel_size": 0.004, "frames": {"start": 1, "end": 400},
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.5], [400, 0.8]]}}})");
    const fs::path dir = mDir / "run";
    const pid_t pid = spawnIvdb(dir, {"rasterize", "big.json", "-o", "b_####.vdb"});
    // Wait (without a fixed sleep) until the third frame is written, then interrupt. Frames are
    // made two at a time: frame 2 may be the one interrupted, after frame 3 was written.
    bool seen = false;
    for (int i = 0; i < 120000 * kSlowdown && !seen; ++i) {
        seen = fs::exists(dir / "b_0003.vdb");
        if (!seen) ::usleep(500);
    }
    ASSERT_TRUE(seen) << slurpFile(dir / ".err.txt");
    ASSERT_EQ(::kill(pid, SIGINT), 0);
    const int code = waitIvdb(pid, 60.0 * kSlowdown);
    const std::string err = slurpFile(dir / ".err.txt"), out = slurpFile(dir / ".out.txt");
    expectNoSanitizerReport(err, "interrupted sequence");
    fs::remove(dir / ".err.txt");
    fs::remove(dir / ".out.txt");
    EXPECT_EQ(code, 128 + SIGINT) << err;
    expectMentions(err, {"ivdb: error: interrupted; ", " of 400 frames are written whole",
                         "--resume carries on"}, "stderr");
    std::size_t frames = 0;
    for (const auto& name : listing()) {
        if (name == "big.json") continue;
        ASSERT_EQ(name.rfind("b_", 0), 0u) << "left behind: " << name;
        ++frames;
        EXPECT_GT(frameOf(name), 0) << name << " is not a whole frame";
    }
    EXPECT_GE(frames, 2u);
    EXPECT_TRUE(fs::exists(dir / "b_0001.vdb"));
    EXPECT_TRUE(fs::exists(dir / "b_0003.vdb"));
    EXPECT_LT(frames, 400u);
    // The stderr count and the summary lines agree with the files.
    expectMentions(err, {std::to_string(frames) + " of 400 frames"}, "stderr");
    std::size_t lines = 0;
    for (std::size_t p = out.find(" frame "); p != std::string::npos; p = out.find(" frame ", p + 1)) ++lines;
    EXPECT_EQ(lines, frames) << out;
    // --resume carries on from there.
    const CliResult r = run({"rasterize", "big.json", "--frames", "1-6", "--resume", "-o", "b_####.vdb", "-q"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    for (int f = 1; f <= 6; ++f) EXPECT_GT(frameOf("b_000" + std::to_string(f) + ".vdb"), 0);
}

TEST_F(TestCliAnimation, SignalsWhileTwoFramesAreBeingWrittenLeaveNoTemporaryFile)
{
    // Frame 1 is written alone; frames 2 and 3 are then written at once and both held inside
    // their first write (tests/faults/WriteFaults.cc "pause:1:2"). The first SIGTERM asks the
    // sequence to stop (it waits for the frames being made), the second ends the process at
    // once: the handler must remove both temporary files, not only the last one opened.
    writeText("grow.json", kGrowing);
    const fs::path dir = mDir / "run";
    const fs::path mark = mDir / "held";
    const pid_t pid = spawnIvdb(dir, {"rasterize", "grow.json", "--frames", "1-6",
                                      "--parallel-frames", "2", "-o", "g_#.vdb"},
        {{"LD_PRELOAD", IVDB_WRITE_FAULTS}, {"IVDB_FAULT", "pause:1:2"}, {"IVDB_FAULT_MARK", mark.string()}});
    for (int i = 0; i < 60000 * kSlowdown && !fs::exists(mark); ++i) ::usleep(1000);
    ASSERT_TRUE(fs::exists(mark)) << slurpFile(dir / ".err.txt");
    std::size_t temporary = 0;
    for (const auto& e : fs::directory_iterator(dir)) temporary += e.path().filename().string().find(".tmp-") != std::string::npos;
    EXPECT_EQ(temporary, 2u) << "two frames being written";
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    // Two signals sent at once may merge into one (standard signals do not queue): the second
    // only once the first is no longer pending.
    for (int i = 0; i < 10000 && signalPending(pid, SIGTERM); ++i) ::usleep(100);
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    const int code = waitIvdb(pid, 60.0 * kSlowdown);
    const std::string err = slurpFile(dir / ".err.txt");
    expectNoSanitizerReport(err, "signals during two writes");
    fs::remove(dir / ".err.txt");
    fs::remove(dir / ".out.txt");
    EXPECT_EQ(code, 128 + SIGTERM) << err;
    for (const auto& name : listing()) {
        EXPECT_EQ(name.find(".tmp-"), std::string::npos) << "left behind: " << name;
        if (name != "grow.json") EXPECT_GT(frameOf(name), 0) << name << " is not a whole frame";
    }
    EXPECT_EQ(frameOf("g_1.vdb"), 1);
}

TEST_F(TestCliAnimation, BadFramesAndKeysAreRefusedAndNothingIsWritten)
{
    writeText("grow.json", kGrowing);
    writeText("still.json", R"({"voxel_size": 0.02, "shape": {"type": "sphere", "radius": 0.5}})");
    writeText("norange.json", R"({"voxel_size": 0.02,
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3], [9, 0.6]]}}})");
    // Valid keys, a radius that reaches 0 at frame 9 and is refused there.
    writeText("shrinks.json", R"({"voxel_size": 0.02,
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.4], [9, 0]]}}})");
    writeText("unsorted.json", R"({"voxel_size": 0.02,
        "shape": {"type": "sphere", "radius": {"keys": [[3, 0.3], [1, 0.6]]}}})");
    writeText("voxel.json", R"({"voxel_size": {"keys": [[1, 0.02], [5, 0.04]]},
        "shape": {"type": "sphere", "radius": 0.5}})");
    writeText("interp.json", R"({"voxel_size": 0.02,
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3]], "interpolation": "ease"}}})");
    writeText("vector.json", R"({"voxel_size": 0.02, "shape": {"type": "sphere", "radius": 0.5,
        "center": {"keys": [[1, [0, 0, 0]], [2, [0, 0]]]}}})");
    writeText("pair.json", R"({"voxel_size": 0.02,
        "shape": {"type": "sphere", "radius": {"keys": [[1, 0.3, 2]]}}})");
    expectFails({"rasterize", "grow.json", "--frames", "1-3"}, "out.vdb",
                {"--output", "needs # where the frame number goes", "3 frames"}, "no #");
    expectFails({"rasterize", "grow.json", "--frames", "5-2"}, "o_#.vdb", {"--frames", "A > B", "5-2"}, "A > B");
    expectFails({"rasterize", "grow.json", "--frames", "1-5:0"}, "o_#.vdb", {"--frames", "STEP"}, "step 0");
    expectFails({"rasterize", "still.json", "--frames", "1-3"}, "o_#.vdb",
                {"--frames", "still.json has no keyed value", "nothing moves"}, "still scene");
    expectFails({"rasterize", "norange.json"}, "o.vdb", {"norange.json has keyed values", "(--frames)"},
                "keyed scene, no frames");
    expectFails({"rasterize", "norange.json"}, "o_#.vdb", {"gives no \"frames\"", "(--frames)"},
                "keyed scene, no range");
    expectFails({"rasterize", "shrinks.json", "--frames", "1-9"}, "o_#.vdb",
                {"shrinks.json: shape.radius: must be > 0, got 0"}, "invalid at the last frame");
    expectFails({"rasterize", "unsorted.json", "--frames", "1-3"}, "o_#.vdb",
                {"unsorted.json: shape.radius.keys[1][0]: key frames must be strictly increasing"}, "unsorted");
    expectFails({"rasterize", "voxel.json", "--frames", "1-3"}, "o_#.vdb",
                {"voxel.json: voxel_size: cannot be keyed"}, "keyed voxel size");
    expectFails({"rasterize", "interp.json", "--frames", "1-3"}, "o_#.vdb",
                {"interp.json: shape.radius.interpolation: must be one of linear, smooth, step"}, "interpolation");
    expectFails({"rasterize", "vector.json", "--frames", "1-3"}, "o_#.vdb",
                {"vector.json: shape.center.keys[1][1]: has 2 numbers but the first key has 3"}, "vector length");
    expectFails({"rasterize", "pair.json", "--frames", "1-3"}, "o_#.vdb",
                {"pair.json: shape.radius.keys[0]: must be a [frame, value] pair"}, "not a pair");
}

} // namespace
} // namespace ivdb::test

// SPDX-License-Identifier: Apache-2.0
// Replays fuzz inputs without libFuzzer: every file named on the command line, or every file in
// a folder named there, goes through the target's LLVMFuzzerTestOneInput once. Built in every
// configuration, so the seed corpus and each crash found stay regression tests. Like libFuzzer's
// -rss_limit_mb, an input that takes the process past 2 GB resident fails the replay (the
// out-of-memory findings: OpenVDB allocating what a damaged count says).
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <sys/resource.h>

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv);
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size);

int main(int argc, char** argv)
{
    LLVMFuzzerInitialize(&argc, &argv);
    namespace fs = std::filesystem;
    std::vector<fs::path> files;
    for (int i = 1; i < argc; ++i) {
        const fs::path p(argv[i]);
        if (fs::is_directory(p)) {
            for (const auto& e : fs::directory_iterator(p)) {
                if (e.is_regular_file()) files.push_back(e.path());
            }
        } else {
            files.push_back(p);
        }
    }
    if (files.empty()) {
        std::fprintf(stderr, "usage: %s FILE|FOLDER... (no inputs found)\n", argv[0]);
        return 2;
    }
    for (const auto& f : files) {
        std::ifstream in(f, std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
        struct rusage usage{};
        ::getrusage(RUSAGE_SELF, &usage);
        const long peakMb = usage.ru_maxrss / 1024;
        if (peakMb > 2048) {
            std::fprintf(stderr, "%s: the process reached %ld MB resident (limit 2048 MB)\n",
                         f.string().c_str(), peakMb);
            return 1;
        }
    }
    std::printf("replayed %zu inputs\n", files.size());
    return 0;
}

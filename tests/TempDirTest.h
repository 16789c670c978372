// SPDX-License-Identifier: Apache-2.0
// A test fixture with a folder of its own, made for each test and removed after it.
#pragma once

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <string>
#include <system_error>

#include <unistd.h>

namespace ivdb::test {

class TempDirTest: public ::testing::Test
{
protected:
    /// @param prefix  names the folder (ivdb-test-PREFIX-PID-N) in the system's temporary folder
    explicit TempDirTest(std::string prefix): mPrefix(std::move(prefix)) {}

    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        mDir = std::filesystem::temp_directory_path() /
               ("ivdb-test-" + mPrefix + "-" + std::to_string(::getpid()) + "-" +
                std::to_string(counter++));
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir);
    }

    void TearDown() override
    {
        std::error_code ec;
        std::filesystem::remove_all(mDir, ec);
    }

    /// A path inside the test's folder.
    std::string path(const std::string& name) const { return (mDir / name).string(); }

    std::filesystem::path mDir;

private:
    std::string mPrefix;
};

} // namespace ivdb::test

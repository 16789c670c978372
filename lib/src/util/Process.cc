// SPDX-License-Identifier: Apache-2.0
#include <ivdb/util/Process.h>

#include <openvdb/Exceptions.h>

#include <cstring>
#include <filesystem>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace ivdb::util {

ProcessResult runProcess(const std::vector<std::string>& args)
{
    int outPipe[2], errPipe[2];
    if (::pipe(outPipe) != 0) OPENVDB_THROW(openvdb::RuntimeError, "pipe failed");
    if (::pipe(errPipe) != 0) {
        ::close(outPipe[0]);
        ::close(outPipe[1]);
        OPENVDB_THROW(openvdb::RuntimeError, "pipe failed");
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, outPipe[1], 1);
    posix_spawn_file_actions_adddup2(&actions, errPipe[1], 2);
    posix_spawn_file_actions_addclose(&actions, outPipe[0]);
    posix_spawn_file_actions_addclose(&actions, errPipe[0]);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid = 0;
    const int rc = ::posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(outPipe[1]);
    ::close(errPipe[1]);
    if (rc != 0) {
        ::close(outPipe[0]);
        ::close(errPipe[0]);
        OPENVDB_THROW(openvdb::RuntimeError, "cannot run " + args[0] + ": " + std::strerror(rc));
    }
    // The child's stdout is short; stderr may be longer: read both to the end.
    auto drain = [](int fd, std::string& s) {
        char buf[4096];
        ssize_t n;
        while ((n = ::read(fd, buf, sizeof(buf))) > 0) s.append(buf, size_t(n));
        ::close(fd);
    };
    ProcessResult result;
    drain(errPipe[0], result.err);
    drain(outPipe[0], result.out);
    int status = 0;
    ::waitpid(pid, &status, 0);
    result.status = WIFSIGNALED(status) ? -WTERMSIG(status) : WEXITSTATUS(status);
    return result;
}

std::string executablePath()
{
    std::error_code ec;
    const std::filesystem::path p = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (ec) {
        OPENVDB_THROW(openvdb::RuntimeError, "cannot find this program's path (/proc/self/exe): " +
                                                 ec.message());
    }
    return p.string();
}

} // namespace ivdb::util

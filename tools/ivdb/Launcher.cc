// SPDX-License-Identifier: Apache-2.0
// `ivdb` as users run it: a launcher that sets the environment the program runs best in
// (transparent huge pages: ../HugePages.h) and replaces itself with the program,
// libexec/ivdb/ivdb beside its own bin/ directory (the same process id, arguments and
// environment). It loads none of OpenVDB, so it adds about a millisecond, where the program,
// with OpenVDB's libraries, takes tens of milliseconds to start (docs/performance.md#huge-pages).
#include "../HugePages.h"

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <string>

#include <unistd.h>

int main(int, char** argv)
{
    char self[PATH_MAX];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
    if (n <= 0) {
        std::fprintf(stderr, "ivdb: error: cannot find this program's path (/proc/self/exe): %s\n",
                     std::strerror(errno));
        return 1;
    }
    self[n] = '\0';
    std::string program(self);
    program.erase(program.rfind('/'));
    program += "/../libexec/ivdb/ivdb";
    ivdb::tools::askForHugePages();
    execv(program.c_str(), argv);
    std::fprintf(stderr,
                 "ivdb: error: cannot run the ivdb program %s: %s (the launcher %s runs it from "
                 "libexec/ivdb/ beside its own directory, where the build and the install put it: "
                 "rebuild or reinstall ivdb)\n",
                 program.c_str(), std::strerror(errno), self);
    return 127;
}

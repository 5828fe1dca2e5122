#include "tools/common/tool_main.h"

#include <cstdio>
#include <csignal>
#include <cstring>
#include <new>

#include "tools/common/version.h"

namespace vox {

int ToolMain(const char* name, int argc, char** argv, int (*run)(int argc, char** argv)) {
  // A reader gone from a pipe (`| head`) fails the write (EPIPE) like any
  // other write error, so the tool removes its temporaries and exits 1,
  // instead of dying with them left behind.
  std::signal(SIGPIPE, SIG_IGN);
  try {
    for (int i = 1; i < argc; ++i) {
      if (std::strcmp(argv[i], "--version") == 0) {
        std::printf("%s\n", VersionLine(name).c_str());
        return std::fflush(stdout) == 0 ? 0 : 1;
      }
    }
    return run(argc, argv);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: out of memory (std::bad_alloc); try smaller sizes or budgets\n",
                 name);
    return 1;
  }
}

}  // namespace vox

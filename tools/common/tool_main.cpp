#include "tools/common/tool_main.h"

#include <cstdio>
#include <cstring>
#include <new>

#include "tools/common/version.h"

namespace vox {

int ToolMain(const char* name, int argc, char** argv, int (*run)(int argc, char** argv)) {
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

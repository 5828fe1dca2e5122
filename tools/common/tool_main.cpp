#include "tools/common/tool_main.h"

#include <cstdio>
#include <new>

namespace vox {

int ToolMain(const char* name, int argc, char** argv, int (*run)(int argc, char** argv)) {
  try {
    return run(argc, argv);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: out of memory (std::bad_alloc); try smaller sizes or budgets\n",
                 name);
    return 1;
  }
}

}  // namespace vox

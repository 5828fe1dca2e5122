// vox-info: prints a store's metadata and statistics, as vdb_print does for
// VDB files.
//
//   vox-info STORE_DIR [--verify] [--cache-mb M]
// Exit status: 0 on success, 1 when the store cannot be read, 2 on bad usage.
#include <cstdint>
#include <cstdio>
#include <new>
#include <optional>
#include <string>

#include "storage/store_info.h"
#include "tools/common/flags.h"

namespace {

constexpr const char* kUsage =
    "usage: vox-info STORE_DIR [--verify] [--cache-mb M]\n"
    "  --verify      decompress and check every brick\n"
    "  --cache-mb M  brick cache budget while verifying (default 64)\n";

struct Options {
  std::string store;
  bool verify = false;
  size_t cache_mb = 64;
};

int Usage(const std::string& msg) {
  std::fprintf(stderr, "vox-info: %s\n%s", msg.c_str(), kUsage);
  return 2;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  Options opt;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--verify") {
      opt.verify = true;
    } else if (a == "--cache-mb") {
      const std::optional<std::string> v = flags.Value();
      if (!v) return Usage("--cache-mb needs a value");
      int64_t mb = 0;
      if (!vox::ParseInt(*v, 1, INT64_MAX >> 20, &mb)) return Usage("bad --cache-mb '" + *v + "'");
      opt.cache_mb = size_t(mb);
    } else if (flags.IsFlag()) {
      return Usage("unknown option '" + a + "'");
    } else if (opt.store.empty()) {
      opt.store = a;
    } else {
      return Usage("more than one store given");
    }
  }
  if (opt.store.empty()) return Usage("no store given");
  auto info = vox::InspectStore(opt.store, opt.verify, opt.cache_mb << 20);
  if (!info.ok()) {
    std::fprintf(stderr, "vox-info: %s\n", info.status().ToString().c_str());
    return 1;
  }
  std::fputs(vox::FormatStoreInfo(*info).c_str(), stdout);
  return 0;
}

// Allocation failures anywhere (an image, a brick, a table sized from input)
// end with a clear message and exit 1, never an abort.
int main(int argc, char** argv) {
  try {
    return RunTool(argc, argv);
  } catch (const std::bad_alloc&) {
    fprintf(stderr, "vox-info: out of memory (std::bad_alloc); try smaller sizes or budgets\n");
    return 1;
  }
}

// vox-info: prints a store's metadata and statistics, as vdb_print does for
// VDB files.
//
//   vox-info STORE_DIR [--verify] [--cache-mb M]
// Exit status: 0 on success, 1 when the store cannot be read, 2 on bad usage.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "storage/store_info.h"

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

int main(int argc, char** argv) {
  Options opt;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--verify") {
      opt.verify = true;
    } else if (a == "--cache-mb") {
      if (i + 1 >= argc) return Usage("--cache-mb needs a value");
      char* end = nullptr;
      long long v = std::strtoll(argv[++i], &end, 10);
      if (*end != '\0' || v < 1) return Usage(std::string("bad --cache-mb '") + argv[i] + "'");
      opt.cache_mb = size_t(v);
    } else if (!a.empty() && a[0] == '-') {
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

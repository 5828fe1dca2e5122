// vox-info: prints a store's metadata and statistics, as vdb_print does for
// VDB files.
//
//   vox-info STORE_DIR [--verify] [--memory-mb M] [--cache-mb M]
// Exit status: 0 on success, 1 when the store cannot be read, 2 on bad usage.
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>

#include "storage/store_budget.h"
#include "storage/store_info.h"
#include "tools/common/flags.h"
#include "tools/common/tool_main.h"

namespace {

constexpr const char* kUsage =
    "usage: vox-info STORE_DIR [--verify] [--memory-mb M] [--cache-mb M]\n"
    "  --verify       decompress and check every brick\n"
    "  --memory-mb M  memory the process may use while verifying, in MiB (or 2G);\n"
    "                 default: the memory cgroup's limit, or 3/4 of MemAvailable\n"
    "  --cache-mb M   brick cache while verifying, inside that budget (default 64)\n";

struct Options {
  std::string store;
  bool verify = false;
  size_t cache_mb = 64;
  uint64_t memory_bytes = 0;  // 0: detected
  bool cache_given = false;
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
      opt.cache_given = true;
    } else if (a == "--memory-mb") {
      const std::optional<std::string> v = flags.Value();
      if (!v) return Usage("--memory-mb needs a value");
      auto bytes = vox::ParseMemorySize("--memory-mb", *v);
      if (!bytes.ok()) return Usage(bytes.status().message());
      opt.memory_bytes = *bytes;
    } else if (flags.IsFlag()) {
      return Usage("unknown option '" + a + "'");
    } else if (opt.store.empty()) {
      opt.store = a;
    } else {
      return Usage("more than one store given");
    }
  }
  if (opt.store.empty()) return Usage("no store given");
  uint64_t cache_bytes = uint64_t(opt.cache_mb) << 20;
  if (opt.verify) {  // the cache must fit the process's memory budget
    vox::Status s = [&]() -> vox::Status {
      VOX_ASSIGN_OR_RETURN(const vox::ProcessBudget budget,
                           vox::ChooseProcessBudget(opt.memory_bytes));
      vox::OpenOptions oo;
      oo.cache_bytes = cache_bytes;
      VOX_ASSIGN_OR_RETURN(auto store, vox::Store::Open(opt.store, oo));
      // The default cache shrinks to what the budget leaves; an explicit one must fit.
      auto split = vox::BudgetReader(store.get(), budget.bytes, 0);
      if (!split.ok()) return split.status();
      if (split->brick_cache < cache_bytes) {
        if (opt.cache_given)
          return vox::InvalidArgumentError(
              "--cache-mb " + std::to_string(opt.cache_mb) + " does not fit the memory budget of " +
              budget.ToString() + ": at most " + std::to_string(split->brick_cache >> 20) + " MiB");
        cache_bytes = split->brick_cache;
      }
      return vox::OkStatus();
    }();
    if (!s.ok()) {
      std::fprintf(stderr, "vox-info: %s\n", s.ToString().c_str());
      return 1;
    }
  }
  auto info = vox::InspectStore(opt.store, opt.verify, cache_bytes);
  if (!info.ok()) {
    std::fprintf(stderr, "vox-info: %s\n", info.status().ToString().c_str());
    return 1;
  }
  std::fputs(vox::FormatStoreInfo(*info).c_str(), stdout);
  return 0;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-info", argc, argv, RunTool); }

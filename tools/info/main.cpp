// vox-info: prints a store's metadata and statistics, as vdb_print does for
// VDB files.
//
//   vox-info STORE_DIR [--verify] [--memory-mb M] [--cache-mb M]
// Exit status: 0 on success, 1 when the store cannot be read, 2 on bad usage.
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "storage/store_budget.h"
#include "storage/store_info.h"
#include "tools/common/cli.h"
#include "tools/common/flags.h"
#include "tools/common/tool_main.h"

namespace {

struct Options {
  std::string store;
  bool verify = false;
  size_t cache_mb = 64;
  uint64_t memory_bytes = 0;  // 0: detected
  bool cache_given = false;
};

constexpr vox::OptionSpec kOptions[] = {
    {"--verify", vox::FlagArity::kSwitch, "", "Verification", "decompress and check every brick"},
    {"--memory-mb", vox::FlagArity::kValue, "M", "Verification",
     "memory the process may use while verifying, in MiB (or 2G); default: the memory cgroup's "
     "limit, or 3/4 of MemAvailable"},
    {"--cache-mb", vox::FlagArity::kValue, "M", "Verification",
     "brick cache while verifying, inside that budget (default 64)"},
};

const vox::CommandLineSpec kCommandLine{
    "vox-info", "vox-info STORE_DIR [--verify] [--memory-mb M] [--cache-mb M]",
    "Prints a store's metadata and statistics, as vdb_print does for VDB files.", kOptions,
    "Exit codes: 0 done, 1 the store cannot be read, 2 bad command line.\n"};

// Applies one option of kOptions.
vox::Status ApplyInfoFlag(Options* opt, const std::string& a, const std::string& v) {
  if (a == "--verify") {
    opt->verify = true;
  } else if (a == "--cache-mb") {
    int64_t mb = 0;
    if (!vox::ParseInt(v, 1, INT64_MAX >> 20, &mb))
      return vox::InvalidArgumentError("bad --cache-mb '" + v + "'");
    opt->cache_mb = size_t(mb);
    opt->cache_given = true;
  } else if (a == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(opt->memory_bytes, vox::ParseMemorySize("--memory-mb", v));
  } else {
    return vox::InvalidArgumentError("unknown option " + a);
  }
  return vox::OkStatus();
}

int UsageError(const std::string& message) {
  return vox::UsageError(kCommandLine.program, message);
}

}  // namespace

static int RunTool(int argc, char** argv) {
  Options opt;
  std::vector<std::string> stores;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return ApplyInfoFlag(&opt, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &stores))
    return *exit_code;
  if (stores.empty()) return UsageError("no store given");
  if (stores.size() > 1) return UsageError("more than one store given");
  opt.store = stores[0];
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

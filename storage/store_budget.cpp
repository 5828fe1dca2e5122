#include "storage/store_budget.h"

#include <malloc.h>
#include <sys/resource.h>

#include <algorithm>
#include <thread>

#include "storage/buffer_pool.h"
#include "storage/internal/store_reader.h"

namespace vox {

std::string ProcessBudget::ToString() const {
  return std::to_string((bytes + kMiB / 2) / kMiB) + " MiB (" + source + ")";
}

namespace {

// glibc gives each thread that allocates concurrently an arena of its own, up
// to 8 per core, each reserving 64 MiB of address space (HEAP_MAX_SIZE).
// Under an address space limit the process keeps to kArenasUnderLimit
// arenas besides the main one (mallopt M_ARENA_MAX), or its threads' arenas
// alone would take hundreds of MiB of the limit.
constexpr uint64_t kArenaAddressSpace = 64 * kMiB;
constexpr int kArenasUnderLimit = 2;

// What RLIMIT_AS leaves for the budget (0: no limit), or an error when it
// leaves nothing.
StatusOr<uint64_t> AddressSpaceLeft(int threads, const ProcessMemory& now) {
  struct rlimit as;
  if (getrlimit(RLIMIT_AS, &as) != 0 || as.rlim_cur == RLIM_INFINITY) return uint64_t(0);
  struct rlimit stack;
  const uint64_t stack_bytes = getrlimit(RLIMIT_STACK, &stack) == 0 && stack.rlim_cur != RLIM_INFINITY
                                   ? uint64_t(stack.rlim_cur)
                                   : 8 * kMiB;
  mallopt(M_ARENA_MAX, kArenasUnderLimit);
  const uint64_t arenas = std::min<uint64_t>(uint64_t(threads), kArenasUnderLimit);
  // One more arena's worth: a new arena maps twice its size before trimming.
  const uint64_t reserve = now.vm_size + (arenas + 1) * kArenaAddressSpace + uint64_t(threads) * stack_bytes;
  const uint64_t limit = uint64_t(as.rlim_cur);
  if (limit <= reserve + 16 * kMiB)
    return ResourceExhaustedError(
        "the address space limit (ulimit -v) of " + std::to_string(limit / kMiB) +
        " MiB leaves no memory budget: the process maps " + std::to_string(now.vm_size / kMiB) +
        " MiB now, and its allocator arenas and " + std::to_string(threads) + " threads' stacks reserve " +
        std::to_string((reserve - now.vm_size) / kMiB) + " MiB more; give it at least " +
        std::to_string((reserve + 64 * kMiB) / kMiB) + " MiB");
  return limit - reserve;
}

}  // namespace

StatusOr<ProcessBudget> ChooseProcessBudget(uint64_t explicit_bytes, int threads) {
  ProcessBudget b;
  if (explicit_bytes > 0) {
    b.bytes = explicit_bytes;
    b.source = "--memory-mb";
  } else {
    VOX_ASSIGN_OR_RETURN(MemoryLimit limit, DetectMemoryLimit());
    const uint64_t avail = limit.mem_available / 4 * 3;
    if (limit.cgroup_bytes != 0 && (avail == 0 || limit.cgroup_bytes <= avail)) {
      b.bytes = limit.cgroup_bytes;
      b.source = "cgroup " + limit.cgroup_file;
    } else if (avail != 0) {
      b.bytes = avail;
      b.source = "3/4 of MemAvailable";
    } else {
      b.bytes = kFallbackMemoryBudget;
      b.source = "no limit found; default";
    }
  }
  if (threads <= 0) threads = int(std::max(1u, std::thread::hardware_concurrency())) + 1;
  const ProcessMemory now = ReadProcessMemory();
  VOX_ASSIGN_OR_RETURN(b.address_space, AddressSpaceLeft(threads, now));
  if (b.address_space != 0 && b.address_space < b.bytes) {
    b.bytes = b.address_space;
    b.source = "ulimit -v, less the process's mappings, arenas and stacks";
  }
  // What the process holds beyond a bare process's share is not the budget's
  // (a detected limit is the whole process's; --memory-mb is the render's own).
  if (explicit_bytes == 0 && now.rss > BudgetInputs::kDefaultProcessBase)
    b.held = now.rss - BudgetInputs::kDefaultProcessBase;
  if (b.held != 0) {
    if (b.held + 16 * kMiB >= b.bytes)
      return ResourceExhaustedError("memory budget of " + std::to_string(b.bytes / kMiB) + " MiB (" +
                                    b.source + "): the process already holds " +
                                    std::to_string(now.rss / kMiB) + " MiB, which leaves nothing to render with");
    b.bytes -= b.held;
    b.source += ", less " + std::to_string((b.held + kMiB / 2) / kMiB) + " MiB held at the start";
  }
  return b;
}

namespace {

// Maps the brick pool for the stores' decoded bricks (their caches' decoded
// part, without the record windows') and the threads' pins.
Status ReservePool(const std::vector<Store*>& stores, const MemoryBudget& b) {
  uint64_t bytes = b.brick_pins;
  for (Store* s : stores) {
    const auto* impl = dynamic_cast<const storage_internal::StoreImpl*>(s);
    bytes += impl != nullptr ? impl->decoded_capacity() : 0;
  }
  return ReserveBrickPool(bytes);
}

}  // namespace

StatusOr<MemoryBudget> BudgetStore(Store* store, uint64_t total, BudgetInputs in) {
  const Store::BrickSizes sizes = store->brick_sizes();
  in.resident_bytes = store->resident_bytes();
  in.max_brick_bytes = sizes.max_decoded;
  in.max_stored_brick_bytes = sizes.max_stored;
  auto b = SplitMemoryBudget(total, in);
  if (!b.ok()) return b.status().WithContext("store '" + store->description() + "'");
  store->SetCacheCapacity(b->brick_cache);
  VOX_RETURN_IF_ERROR(ReservePool({store}, *b));
  return b;
}

StatusOr<MemoryBudget> BudgetStores(Store* base, const std::vector<Store*>& levels,
                                    uint64_t total, BudgetInputs in, int first_level) {
  if (levels.empty()) return BudgetStore(base, total, in);
  std::vector<Store*> all{base};
  all.insert(all.end(), levels.begin(), levels.end());
  in.resident_bytes = 0;
  in.max_brick_bytes = in.max_stored_brick_bytes = 0;
  std::vector<double> weight;
  double sum = 0;
  first_level = std::clamp(first_level, 0, int(levels.size()));
  for (size_t i = 0; i < all.size(); ++i) {
    Store* s = all[i];
    const Store::BrickSizes sizes = s->brick_sizes();
    in.resident_bytes += s->resident_bytes();
    in.max_brick_bytes = std::max(in.max_brick_bytes, sizes.max_decoded);
    in.max_stored_brick_bytes = std::max(in.max_stored_brick_bytes, sizes.max_stored);
    const bool used = int(i) >= first_level;
    weight.push_back(used ? double(s->meta().brick_count) * double(sizes.mean_decoded) + 1.0 : 0.0);
    sum += weight.back();
  }
  // Each store at least kMinShare of the cache: the split's floor, so a
  // budget too small for it is refused naming the whole budget it needs.
  constexpr uint64_t kMinShare = 4 * kMiB;
  const uint64_t n = all.size();
  in.min_cache_bytes = std::max(in.min_cache_bytes, n * kMinShare);
  auto b = SplitMemoryBudget(total, in);
  if (!b.ok())
    return b.status().WithContext("store '" + base->description() + "' and its " +
                                  std::to_string(levels.size()) +
                                  "-level pyramid (a brick cache of " +
                                  std::to_string(kMinShare / kMiB) + " MiB or more for each)");
  // The split refuses an explicit --cache-mb below the floor, so this cannot happen.
  if (b->brick_cache < n * kMinShare) return InternalError("brick cache below the pyramid's floor");
  // Each store its minimum, the rest in proportion: the shares sum to at most the cache.
  const uint64_t rest = b->brick_cache - n * kMinShare;
  for (size_t i = 0; i < all.size(); ++i)
    all[i]->SetCacheCapacity(kMinShare + uint64_t(double(rest) * (weight[i] / sum)));
  VOX_RETURN_IF_ERROR(ReservePool(all, *b));
  return b;
}

StatusOr<MemoryBudget> BudgetReader(Store* store, uint64_t total, uint64_t cache_override) {
  BudgetInputs in;
  in.image_width = in.image_height = 1;
  in.tile_size = 1;
  in.channels = 1;
  in.threads = 1;
  in.cache_override = cache_override;
  return BudgetStore(store, total, in);
}

}  // namespace vox

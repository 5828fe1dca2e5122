#include "storage/store_budget.h"

#include <algorithm>

namespace vox {

std::string ProcessBudget::ToString() const {
  return std::to_string((bytes + kMiB / 2) / kMiB) + " MiB (" + source + ")";
}

StatusOr<ProcessBudget> ChooseProcessBudget(uint64_t explicit_bytes) {
  ProcessBudget b;
  if (explicit_bytes > 0) {
    b.bytes = explicit_bytes;
    b.source = "--memory-mb";
    return b;
  }
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
  return b;
}

StatusOr<MemoryBudget> BudgetStore(Store* store, uint64_t total, BudgetInputs in) {
  const Store::BrickSizes sizes = store->brick_sizes();
  in.resident_bytes = store->resident_bytes();
  in.max_brick_bytes = sizes.max_decoded;
  in.max_stored_brick_bytes = sizes.max_stored;
  auto b = SplitMemoryBudget(total, in);
  if (!b.ok()) return b.status().WithContext("store '" + store->description() + "'");
  store->SetCacheCapacity(b->brick_cache);
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
  auto b = SplitMemoryBudget(total, in);
  if (!b.ok()) return b.status().WithContext("store '" + base->description() + "' and its pyramid");
  constexpr uint64_t kMinShare = 4 * kMiB;
  const uint64_t n = all.size();
  if (b->brick_cache < n * kMinShare)
    return ResourceExhaustedError("store '" + base->description() + "' with its " +
                                  std::to_string(levels.size()) +
                                  "-level pyramid needs a brick cache of at least " +
                                  std::to_string(n * kMinShare / kMiB) + " MiB; the budget leaves " +
                                  std::to_string(b->brick_cache / kMiB) + " MiB");
  // Each store its minimum, the rest in proportion: the shares sum to at most the cache.
  const uint64_t rest = b->brick_cache - n * kMinShare;
  for (size_t i = 0; i < all.size(); ++i)
    all[i]->SetCacheCapacity(kMinShare + uint64_t(double(rest) * (weight[i] / sum)));
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

// vox::ChooseProcessBudget and vox::BudgetStore: the one memory budget of a
// program that opens a store (vox-render, vox-probe, vox-info --verify), and
// the brick cache sized from it once the store's resident top is known.
//
// The budget is --memory-mb when given; otherwise the memory cgroup's limit
// (Slurm --mem, a container; core/util/memory_budget.h finds it), or 3/4 of
// MemAvailable when that is smaller or there is no cgroup limit (the rest is
// left to other processes and the kernel); 4 GiB when neither is known.
// Under an address space limit (RLIMIT_AS, `ulimit -v`) it is at most what
// the limit leaves once the process's mappings now, glibc's arenas (64 MiB
// of address space each; capped at 2 besides the main one under such a
// limit, mallopt M_ARENA_MAX) and the threads' stacks are counted. What the process already holds at the start (its resident set
// beyond the 24 MiB a bare process is counted as: a Python session's arrays)
// is taken off a detected limit, which is the whole process's (--memory-mb
// is taken as the render's own budget). SplitMemoryBudget keeps
// 1/8 of it as headroom and 24 MiB for the process itself.
//
// The brick cache's decoded bricks and the threads' pins live in the
// process's brick pool (storage/buffer_pool.h), mapped once at the budget's
// size for them, so the heap does not fragment under a churning cache.
//
// Thread safety: free functions; BudgetStore must not race with the store's
// readers (call it after open, before reading bricks).
#ifndef VOX_STORAGE_STORE_BUDGET_H_
#define VOX_STORAGE_STORE_BUDGET_H_

#include <cstdint>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "core/util/memory_budget.h"
#include "storage/store.h"

namespace vox {

struct ProcessBudget {
  uint64_t bytes = 0;
  uint64_t held = 0;           // taken off for what the process held at the start
  uint64_t address_space = 0;  // what RLIMIT_AS leaves (0: no such limit)
  std::string source;  // where it came from, e.g. "--memory-mb", "cgroup /sys/fs/...", "3/4 of MemAvailable"
  std::string ToString() const;  // "768 MiB (cgroup ...)"
};

inline constexpr uint64_t kFallbackMemoryBudget = uint64_t(4) << 30;

// `explicit_bytes` > 0: that (from --memory-mb); 0: detected as above.
// `threads`: the threads the process will run (0: the cores, plus one).
// Errors: an unparseable cgroup or meminfo file (named); ResourceExhausted
// when what the process holds, or its address space limit, leaves nothing.
StatusOr<ProcessBudget> ChooseProcessBudget(uint64_t explicit_bytes, int threads = 0);

// Splits `total` for a reader of `store` (in's store fields are filled in
// from it: resident bytes, brick sizes) and sets the store's cache capacity
// to the split's brick cache. ResourceExhaustedError naming the store and
// the MiB it needs when its resident top and minimal cache do not fit.
StatusOr<MemoryBudget> BudgetStore(Store* store, uint64_t total, BudgetInputs in);

// The same for a base store and the coarse stores of its level-of-detail
// pyramid (storage/lod.h), which share one budget: resident tops add up,
// the largest brick of any sizes the pins, and the brick cache is divided
// among the stores in proportion to their decoded bricks (each at least 4
// MiB), never more than the split's cache in all. `first_level`: the
// finest level the frame can use (0: the base; levels[l - 1] is level l);
// the finer stores get only the minimum, the rest is shared by the others.
StatusOr<MemoryBudget> BudgetStores(Store* base, const std::vector<Store*>& levels,
                                    uint64_t total, BudgetInputs in, int first_level = 0);

// The same for a reader that renders no image, on one thread (vox-probe,
// vox-info --verify); `cache_override` as BudgetInputs::cache_override.
StatusOr<MemoryBudget> BudgetReader(Store* store, uint64_t total, uint64_t cache_override);

}  // namespace vox

#endif  // VOX_STORAGE_STORE_BUDGET_H_

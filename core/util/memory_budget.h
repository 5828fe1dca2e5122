// vox::DetectMemoryLimit, vox::ParseMemorySize, vox::SplitMemoryBudget,
// vox::ReadProcessMemory and vox::HeapWatch:
// how much memory a process may really use (its memory cgroup's limit, v1 or
// v2, and the kernel's MemAvailable; the smaller wins), parsing a
// `--memory-mb`-style flag, and the split of one process budget between the
// parts of a render that hold memory. A job killed by the cgroup's OOM killer loses all its work, so a
// reader sizes its caches from this budget, not from a fixed default.
//
// Thread safety: free functions without shared state; thread-safe. The
// structs are plain values; HeapWatch is thread-safe.
#ifndef VOX_CORE_UTIL_MEMORY_BUDGET_H_
#define VOX_CORE_UTIL_MEMORY_BUDGET_H_

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace vox {

constexpr uint64_t kMiB = uint64_t(1) << 20;

// The largest read a prefetching I/O thread makes at once (Store::Prefetch
// merges neighbouring bricks into runs of at most this many bytes).
constexpr uint64_t kPrefetchRunBytes = uint64_t(1) << 20;

// The largest window of brick records a reader reads at once
// (OpenOptions::read_windows; storage/internal/record_windows.h).
constexpr uint64_t kMaxReadWindowBytes = uint64_t(1) << 20;

// What the process may use, in bytes. 0 in a field means "none found".
struct MemoryLimit {
  uint64_t bytes = 0;          // the smallest of the limits below that exist (0: none known)
  uint64_t cgroup_bytes = 0;   // the tightest limit on the process's cgroup and its ancestors
  std::string cgroup_file;     // the file that gave cgroup_bytes (under the root given)
  uint64_t mem_available = 0;  // MemAvailable of /proc/meminfo
  std::string ToString() const;  // e.g. "768 MiB (cgroup v1 .../memory.limit_in_bytes)"
};

// Reads `root`/proc/self/cgroup, `root`/proc/self/mountinfo, the memory
// controller's files under the mount points (prefixed with `root`) and
// `root`/proc/meminfo. cgroup v1: memory.limit_in_bytes; v2: memory.max;
// each level from the process's cgroup up to its hierarchy's root counts (a
// parent's limit binds its children). "max" and values of 2^62 or more mean
// unlimited. Missing files are not errors (no cgroup, no meminfo: 0); a file
// that exists but cannot be parsed is a CorruptionError naming it.
StatusOr<MemoryLimit> DetectMemoryLimit(const std::string& root = "/");

// What the process holds now, to set against its budget: the kernel's view
// (/proc/self/status: VmHWM, the peak resident set, VmRSS and VmSize now,
// and RssAnon, the anonymous part now) and the allocator's (glibc mallinfo2: bytes it holds
// from the system and bytes in live allocations; the difference is free
// memory it keeps, the fragmentation a churning cache leaves). A field is 0
// where it cannot be read.
struct ProcessMemory {
  uint64_t peak_rss = 0;
  uint64_t rss = 0;       // VmRSS: the resident set now
  uint64_t vm_size = 0;   // VmSize: the address space mapped now (what RLIMIT_AS limits)
  uint64_t rss_anon = 0;
  uint64_t heap_held = 0;
  uint64_t heap_in_use = 0;
  std::string ToJson() const;
};
ProcessMemory ReadProcessMemory();

// The process's anonymous memory held against what its budget planned for
// it. A brick cache that churns frees blocks of many sizes between live ones,
// and the allocator keeps them: measured on the 16384^3 sphere's exact full
// view in 256 MiB, the heap held 238.7 MiB for 182.6 MiB in use, memory no
// budget line counts. Giving the pages back (malloc_trim) cost 25-55% of the
// frame. So stores ask the watch, as they load bricks, how much of their
// cache to give up instead: whatever the anonymous memory grew past the
// target since its last answer (docs/scale.md, "The allocator's
// share"). Thread-safe; one instance per process.
class HeapWatch {
 public:
  static HeapWatch& Process();

  // The anonymous memory the process may hold (0: no watch, the default).
  // Also forgets the growth already answered for.
  void SetTarget(uint64_t anon_bytes);
  uint64_t target() const { return target_.load(std::memory_order_relaxed); }

  // Called by a store with the bytes it just loaded. Every kCheckBytes
  // loaded in the process, reads the anonymous resident memory
  // (/proc/self/statm) and returns Absorb's answer; 0 otherwise.
  static constexpr uint64_t kCheckBytes = uint64_t(4) << 20;
  uint64_t Loaded(uint64_t bytes);

  // The policy: bytes to give up for a reading of `anon` bytes, that is its
  // growth past max(target, the highest reading answered for before); 0
  // without a target.
  uint64_t Absorb(uint64_t anon);

  // Bytes answered for since the target was set.
  uint64_t given_up() const { return given_up_.load(std::memory_order_relaxed); }

 private:
  std::atomic<uint64_t> target_{0}, loaded_{0}, given_up_{0};
  std::mutex mu_;
  uint64_t high_ = 0;  // under mu_
};

// Parses a memory size for `flag` (named in errors): a positive number of
// MiB ("512"), or a number with a binary unit K, M, G or T, optionally
// followed by "iB" or "B", any case ("512M", "2G", "1.5GiB", "65536K").
// Fractions are allowed with a unit. Errors: empty, non-numeric, negative,
// zero, below 1 MiB, unknown unit, or more than 2^62 bytes.
StatusOr<uint64_t> ParseMemorySize(std::string_view flag, std::string_view text);

// What a render holds besides its brick cache.
struct BudgetInputs {
  uint64_t resident_bytes = 0;    // the store's resident top: Store::resident_bytes()
  uint64_t max_brick_bytes = 0;   // the largest brick as the cache holds it (decoded)
  uint64_t max_stored_brick_bytes = 0;  // the largest brick record on disk
  int image_width = 0, image_height = 0;
  int tile_size = 64;
  int threads = 1;
  int io_threads = 0;             // prefetching I/O threads (0: no prefetch)
  // The largest record window a miss reads (0: records read alone): each
  // thread's read in flight holds it in a buffer and in the page cache.
  uint64_t read_window_bytes = kMaxReadWindowBytes;
  int channels = 5;               // EXR channels: R G B A Z, + 3 per extra layer
  // Pins wanted per thread table (a power of two, 1..256); the split lowers
  // it until the tables fit their share (1/8 of what the fixed costs leave).
  int pins_per_thread = 256;
  // A floor for the brick cache above MinBrickCacheBytes's own (a store and
  // its pyramid's levels, each with a minimal share); 0: none.
  uint64_t min_cache_bytes = 0;
  // An explicit brick cache size (--cache-mb); 0: the rest. Must fit
  // in what the fixed costs leave.
  uint64_t cache_override = 0;
  // Code, libraries, stacks, allocator and decoder state of the process that
  // do not scale with the image or the store: a measured base plus a margin
  // for more threads and other allocators (docs/performance.md).
  uint64_t process_base = kDefaultProcessBase;
  static constexpr uint64_t kDefaultProcessBase = 24 * kMiB;
};

// One process budget, split. All in bytes; the parts sum to `total`.
struct MemoryBudget {
  uint64_t total = 0;
  uint64_t process_base = 0;   // fixed: code, libraries, stacks, allocator
  uint64_t headroom = 0;       // 1/8 of total: fragmentation and estimates' error (1/16 was
                               // too little: docs/performance.md)
  uint64_t resident_top = 0;   // the store's top and brick table
  uint64_t tile_buffers = 0;   // one TileBuffer per thread
  uint64_t exr_writer = 0;     // compressed tiles in flight, offset table, preview rows
  uint64_t page_cache = 0;     // the brick file's pages of reads in flight (charged to the cgroup)
  uint64_t brick_pins = 0;     // threads x pins_per_thread x max_brick_bytes
  uint64_t brick_cache = 0;    // the shared decompressed-brick cache
  uint64_t unused = 0;         // left over when cache_override is below the rest
  int pins_per_thread = 0;
  // "budget 768 MiB: base 24, headroom 48, top 0.1, tiles 0.3, exr 1.2, page
  // cache 2.0, pins 20.0 (16/thread), cache 672.4 MiB"
  std::string ToString() const;
  std::string ToJson() const;  // one object, byte counts, for --stats
};

// The smallest brick cache a split allows: enough for each thread to hold
// a few bricks while others load, and at least in.min_cache_bytes.
uint64_t MinBrickCacheBytes(const BudgetInputs& in);

// Splits `total` bytes (e.g. DetectMemoryLimit().bytes, or --memory-mb):
//   fixed = process_base + headroom + resident_top + tile_buffers +
//           exr_writer + page_cache
//   pins  = threads x pins_per_thread x max_brick_bytes, pins_per_thread
//           halved until pins <= (total - fixed) / 8 (at least 1)
//   cache = total - fixed - pins (or cache_override, if it fits)
// ResourceExhaustedError when the cache would fall below
// MinBrickCacheBytes, saying how many MiB the render needs at least;
// InvalidArgumentError for inputs that make no sense or a cache_override
// larger than what is left.
StatusOr<MemoryBudget> SplitMemoryBudget(uint64_t total, const BudgetInputs& in);

}  // namespace vox

#endif  // VOX_CORE_UTIL_MEMORY_BUDGET_H_

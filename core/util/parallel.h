// vox's one seam to threads: every tile worker of a render, the ingest's and
// vox-gen's brick pipelines and every parallel loop run through these calls.
//
// A normal build runs them on TBB. Configured with -DVOX_PLAIN_THREADS=ON
// (the ThreadSanitizer build, scripts/sanitize.sh tsan), they run on plain
// std::threads with the same semantics: ThreadSanitizer sees every hand-off
// of a std::thread and a mutex, but not those inside an uninstrumented TBB,
// so only there can it judge vox's own code.
//
// Semantics common to both executors:
//   - threads: 0 means DefaultThreads(); no call uses more than it is given.
//   - exceptions: the first exception a task throws stops what has not
//     started yet and is rethrown to the caller once every running task
//     has returned.
//   - the calling thread takes part in the work.
//
// Thread safety: every function may be called from any thread, also from
// inside a task (nested).
#ifndef VOX_CORE_UTIL_PARALLEL_H_
#define VOX_CORE_UTIL_PARALLEL_H_

#include <cstddef>
#include <functional>
#include <vector>

namespace vox {

// True in a build with -DVOX_PLAIN_THREADS=ON (std::thread, no TBB scheduler).
bool PlainThreads();

// The threads a call with threads = 0 uses: inside WithThreadLimit its
// limit, otherwise the machine's cores (TBB's default concurrency).
int DefaultThreads();

// Runs fn with the calls above and, in TBB builds, TBB-based libraries
// (OpenVDB's own parallel loops) limited to `threads` threads (0: no limit).
void WithThreadLimit(int threads, const std::function<void()>& fn);

// Runs fn(0) ... fn(n-1), each once, on up to n threads (the calling thread
// included), and returns when all have returned. Each task is a worker that
// takes its work from shared state until none is left, so a task must not
// wait for another (TBB may run two of them one after the other on one
// thread). An exception from one stops the tasks not yet started.
void RunWorkers(int n, const std::function<void(int)>& fn);

// Calls fn(b, e) on disjoint subranges [b, e) covering [begin, end), each at
// most `grain` long (grain 0: 1), on up to `threads` threads.
void ParallelFor(size_t begin, size_t end, size_t grain,
                 const std::function<void(size_t, size_t)>& fn, int threads = 0);

namespace parallel_internal {
// The pipeline of RunPipeline over slot indices 0 .. tokens-1.
void RunSlotPipeline(int threads, size_t tokens, const std::function<bool(size_t)>& source,
                     const std::function<void(size_t)>& work,
                     const std::function<void(size_t)>& sink);
}  // namespace parallel_internal

// A three-stage pipeline on up to `threads` threads with at most `tokens`
// items in flight (tokens 0: 1):
//   source(item): serial, in order; fills a default-constructed item and
//                 returns true, or returns false when there are no more;
//   work(item):   in parallel;
//   sink(item):   serial, in the order source made the items.
// To stop early, make source return false (earlier items still finish).
template <class Item>
void RunPipeline(int threads, size_t tokens, const std::function<bool(Item&)>& source,
                 const std::function<void(Item&)>& work, const std::function<void(Item&)>& sink) {
  if (tokens == 0) tokens = 1;
  std::vector<Item> slots(tokens);
  parallel_internal::RunSlotPipeline(
      threads, tokens,
      [&](size_t s) {
        slots[s] = Item{};
        return source(slots[s]);
      },
      [&](size_t s) { work(slots[s]); },
      [&](size_t s) {
        sink(slots[s]);
        slots[s] = Item{};  // free what the item holds before the slot's next use
      });
}

}  // namespace vox

#endif  // VOX_CORE_UTIL_PARALLEL_H_

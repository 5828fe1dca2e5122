#include "core/util/parallel.h"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>

#ifndef VOX_PLAIN_THREADS
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>
#endif

namespace vox {
namespace {

// The pipeline's free slots: the source takes one per item, the sink gives
// it back. There is always one for the source, as no more than `tokens`
// items are in flight.
class SlotPool {
 public:
  explicit SlotPool(size_t tokens) {
    for (size_t s = tokens; s-- > 0;) free_.push_back(s);
  }
  size_t Take() {
    std::lock_guard<std::mutex> lock(mu_);
    const size_t s = free_.back();
    free_.pop_back();
    return s;
  }
  void Give(size_t s) {
    std::lock_guard<std::mutex> lock(mu_);
    free_.push_back(s);
  }

 private:
  std::mutex mu_;
  std::vector<size_t> free_;
};

}  // namespace

#ifdef VOX_PLAIN_THREADS

namespace {

// The limit of WithThreadLimit, and inside RunWorkers the task count, as a
// TBB arena's concurrency is inside it (0: none).
thread_local int t_limit = 0;

class ScopedLimit {
 public:
  explicit ScopedLimit(int threads) : saved_(t_limit) {
    if (threads > 0) t_limit = threads;
  }
  ~ScopedLimit() { t_limit = saved_; }

 private:
  int saved_;
};

int Threads(int threads) { return threads > 0 ? threads : DefaultThreads(); }

}  // namespace

bool PlainThreads() { return true; }

int DefaultThreads() {
  return t_limit > 0 ? t_limit : int(std::max(1u, std::thread::hardware_concurrency()));
}

void WithThreadLimit(int threads, const std::function<void()>& fn) {
  ScopedLimit limit(threads);
  fn();
}

void RunWorkers(int n, const std::function<void(int)>& fn) {
  n = std::max(n, 1);
  std::atomic<bool> stop{false};
  std::mutex mu;
  std::exception_ptr error;
  auto run = [&](int i) {
    ScopedLimit limit(n);
    if (stop.load()) return;
    try {
      fn(i);
    } catch (...) {
      std::lock_guard<std::mutex> lock(mu);
      if (!error) error = std::current_exception();
      stop = true;
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(size_t(n - 1));
  try {
    for (int i = 1; i < n; ++i) threads.emplace_back(run, i);
  } catch (...) {  // no thread to be had: those started finish, the rest is not run
    stop = true;
    for (std::thread& t : threads) t.join();
    throw;
  }
  run(0);
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
}

void ParallelFor(size_t begin, size_t end, size_t grain,
                 const std::function<void(size_t, size_t)>& fn, int threads) {
  if (end <= begin) return;
  grain = std::max<size_t>(grain, 1);
  const size_t chunks = (end - begin + grain - 1) / grain;
  std::atomic<size_t> next{0};
  std::atomic<bool> stop{false};
  RunWorkers(int(std::min<size_t>(size_t(Threads(threads)), chunks)), [&](int) {
    try {
      for (size_t c; !stop.load() && (c = next.fetch_add(1)) < chunks;) {
        const size_t b = begin + c * grain;
        fn(b, std::min(end, b + grain));
      }
    } catch (...) {
      stop = true;
      throw;
    }
  });
}

namespace parallel_internal {

// Each thread loops: sink the next item in order if it is ready, else take
// the source's turn and work on the item it made, else wait. Every hand-over
// is under mu, so ThreadSanitizer sees it.
void RunSlotPipeline(int threads, size_t tokens, const std::function<bool(size_t)>& source,
                     const std::function<void(size_t)>& work,
                     const std::function<void(size_t)>& sink) {
  tokens = std::max<size_t>(tokens, 1);
  std::mutex mu;
  std::condition_variable cv;
  SlotPool pool(tokens);
  size_t free_slots = tokens;
  std::vector<uint64_t> seq(tokens, 0);
  std::vector<char> ready(tokens, 0);
  uint64_t next_seq = 0, next_sink = 0;
  bool sourcing = false, sinking = false, ended = false, failed = false;
  std::exception_ptr error;

  auto worker = [&](int) {
    std::unique_lock<std::mutex> lock(mu);
    // Runs f unlocked; false (and the pipeline failed) if it threw.
    auto call = [&](const std::function<void()>& f) {
      lock.unlock();
      std::exception_ptr e;
      try {
        f();
      } catch (...) {
        e = std::current_exception();
      }
      lock.lock();
      if (!e) return true;
      if (!error) error = e;
      failed = true;
      cv.notify_all();
      return false;
    };
    for (;;) {
      if (failed) return;
      if (!sinking) {
        size_t s = 0;
        while (s < tokens && !(ready[s] && seq[s] == next_sink)) ++s;
        if (s < tokens) {
          sinking = true;
          ready[s] = 0;
          if (!call([&] { sink(s); })) return;
          sinking = false;
          ++next_sink;
          pool.Give(s);
          ++free_slots;
          cv.notify_all();
          continue;
        }
      }
      if (!sourcing && !ended && free_slots > 0) {
        const size_t s = pool.Take();
        --free_slots;
        sourcing = true;
        bool more = false;
        if (!call([&] { more = source(s); })) return;
        sourcing = false;
        if (!more) {
          ended = true;
          pool.Give(s);
          ++free_slots;
        } else {
          seq[s] = next_seq++;
        }
        cv.notify_all();  // the source's turn is free
        if (!more) continue;
        if (!call([&] { work(s); })) return;
        ready[s] = 1;
        cv.notify_all();
        continue;
      }
      if (ended && next_sink == next_seq) return;
      cv.wait(lock);
    }
  };
  const int t = Threads(threads);
  RunWorkers(int(std::min<size_t>(size_t(t), tokens)), worker);
  if (error) std::rethrow_exception(error);
}

}  // namespace parallel_internal

#else  // TBB

namespace {

// Runs fn in an arena of `threads` (0: the current one).
template <class Fn>
void InArena(int threads, const Fn& fn) {
  if (threads <= 0) return fn();
  tbb::task_arena arena(threads);
  arena.execute(fn);
}

}  // namespace

bool PlainThreads() { return false; }

int DefaultThreads() { return tbb::this_task_arena::max_concurrency(); }

void WithThreadLimit(int threads, const std::function<void()>& fn) { InArena(threads, fn); }

void RunWorkers(int n, const std::function<void(int)>& fn) {
  n = std::max(n, 1);
  InArena(n, [&] { tbb::parallel_for(0, n, [&](int i) { fn(i); }); });
}

void ParallelFor(size_t begin, size_t end, size_t grain,
                 const std::function<void(size_t, size_t)>& fn, int threads) {
  if (end <= begin) return;
  grain = std::max<size_t>(grain, 1);
  InArena(threads, [&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(begin, end, grain),
        [&](const tbb::blocked_range<size_t>& r) { fn(r.begin(), r.end()); },
        tbb::simple_partitioner());
  });
}

namespace parallel_internal {

void RunSlotPipeline(int threads, size_t tokens, const std::function<bool(size_t)>& source,
                     const std::function<void(size_t)>& work,
                     const std::function<void(size_t)>& sink) {
  tokens = std::max<size_t>(tokens, 1);
  SlotPool pool(tokens);
  InArena(threads, [&] {
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, size_t>(tbb::filter_mode::serial_in_order,
                                       [&](tbb::flow_control& fc) -> size_t {
                                         const size_t s = pool.Take();
                                         if (source(s)) return s;
                                         pool.Give(s);
                                         fc.stop();
                                         return 0;
                                       }) &
            tbb::make_filter<size_t, size_t>(tbb::filter_mode::parallel,
                                             [&](size_t s) {
                                               work(s);
                                               return s;
                                             }) &
            tbb::make_filter<size_t, void>(tbb::filter_mode::serial_in_order, [&](size_t s) {
              sink(s);
              pool.Give(s);
            }));
  });
}

}  // namespace parallel_internal

#endif

}  // namespace vox

// The seam to threads (core/util/parallel.h), in whichever executor the build
// has (TBB; std::thread with VOX_PLAIN_THREADS, as in the TSan stage, which
// runs this test too): every task once, results in order, no more threads
// than asked, the first exception rethrown, and what is not started after it
// not started.
#include "core/util/parallel.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

namespace vox {
namespace {

// Counts the tasks running at once and keeps the most seen.
class Concurrency {
 public:
  void Enter() {
    const int now = ++active_;
    int seen = most_.load();
    while (now > seen && !most_.compare_exchange_weak(seen, now)) {
    }
    // Long enough that other threads start meanwhile.
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  void Leave() { --active_; }
  int most() const { return most_.load(); }

 private:
  std::atomic<int> active_{0}, most_{0};
};

TEST(Parallel, RunWorkersRunsEveryIndexOnceOnAtMostNThreads) {
  for (int n : {1, 2, 3, 8}) {
    std::vector<std::atomic<int>> calls(static_cast<size_t>(n));
    Concurrency c;
    RunWorkers(n, [&](int i) {
      c.Enter();
      ++calls[size_t(i)];
      c.Leave();
    });
    for (int i = 0; i < n; ++i) EXPECT_EQ(calls[size_t(i)].load(), 1) << "n " << n << " i " << i;
    EXPECT_LE(c.most(), n);
    EXPECT_GE(c.most(), 1);
  }
}

TEST(Parallel, RunWorkersSharesWorkAndRunsInParallel) {
  // Workers pull items from a shared cursor, as the tile workers do.
  const int kItems = 200;
  std::atomic<int> cursor{0};
  std::vector<int> done(kItems, 0);
  std::mutex mu;
  Concurrency c;
  RunWorkers(4, [&](int) {
    for (int i; (i = cursor.fetch_add(1)) < kItems;) {
      c.Enter();
      {
        std::lock_guard<std::mutex> lock(mu);
        ++done[size_t(i)];
      }
      c.Leave();
    }
  });
  EXPECT_EQ(std::count(done.begin(), done.end(), 1), kItems);
  EXPECT_LE(c.most(), 4);
  if (std::thread::hardware_concurrency() > 1) {
    EXPECT_GE(c.most(), 2);
  }
}

TEST(Parallel, RunWorkersRethrowsTheException) {
  std::atomic<int> finished{0};
  try {
    RunWorkers(3, [&](int i) {
      if (i == 1) throw std::runtime_error("worker 1 failed");
      ++finished;
    });
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "worker 1 failed");
  }
  EXPECT_LE(finished.load(), 2);
}

TEST(Parallel, DefaultThreadsFollowsTheLimit) {
  EXPECT_GE(DefaultThreads(), 1);
  int inside = 0, nested = 0;
  WithThreadLimit(3, [&] {
    inside = DefaultThreads();
    RunWorkers(1, [&](int) { nested = DefaultThreads(); });
  });
  EXPECT_EQ(inside, 3);
  EXPECT_EQ(nested, 1);
  std::atomic<int> in_workers{0};
  RunWorkers(2, [&](int) { in_workers = DefaultThreads(); });
  EXPECT_EQ(in_workers.load(), 2);
  int zero = 0;
  WithThreadLimit(0, [&] { zero = DefaultThreads(); });
  EXPECT_EQ(zero, DefaultThreads());  // 0: no limit
}

TEST(Parallel, ParallelForCoversTheRangeInGrainsOnAtMostThreads) {
  const size_t kBegin = 7, kEnd = 1007;
  std::vector<std::atomic<int>> hits(kEnd);
  std::atomic<size_t> longest{0};
  Concurrency c;
  ParallelFor(
      kBegin, kEnd, 16,
      [&](size_t b, size_t e) {
        c.Enter();
        ASSERT_LT(b, e);
        size_t len = e - b, seen = longest.load();
        while (len > seen && !longest.compare_exchange_weak(seen, len)) {
        }
        for (size_t i = b; i < e; ++i) ++hits[i];
        c.Leave();
      },
      3);
  for (size_t i = 0; i < kEnd; ++i) EXPECT_EQ(hits[i].load(), i < kBegin ? 0 : 1) << i;
  EXPECT_LE(longest.load(), 16u);
  EXPECT_LE(c.most(), 3);
  ParallelFor(5, 5, 1, [&](size_t, size_t) { FAIL() << "called on an empty range"; });
}

TEST(Parallel, ParallelForRethrowsAndStops) {
  std::atomic<int> calls{0};
  EXPECT_THROW(ParallelFor(
                   0, 100000, 1,
                   [&](size_t b, size_t) {
                     ++calls;
                     if (b == 3) throw std::out_of_range("three");
                   },
                   2),
               std::out_of_range);
  EXPECT_LT(calls.load(), 100000);  // what was not started is not run
}

struct Item {
  int index = -1;
  int value = 0;
};

TEST(Parallel, PipelineSinksInSourceOrderWithBoundedItemsInFlight) {
  for (int threads : {1, 2, 4}) {
    const int kItems = 300;
    const size_t kTokens = 3;
    int next = 0;
    std::atomic<int> in_flight{0}, most_in_flight{0};
    std::vector<int> sunk;
    Concurrency c;
    RunPipeline<Item>(
        threads, kTokens,
        [&](Item& it) {
          EXPECT_EQ(it.index, -1);  // a fresh item
          if (next == kItems) return false;
          it.index = next++;
          const int now = ++in_flight;
          most_in_flight = std::max(most_in_flight.load(), now);
          return true;
        },
        [&](Item& it) {
          c.Enter();
          it.value = it.index * it.index;
          c.Leave();
        },
        [&](Item& it) {
          EXPECT_EQ(it.value, it.index * it.index);
          sunk.push_back(it.index);
          --in_flight;
        });
    ASSERT_EQ(int(sunk.size()), kItems) << "threads " << threads;
    for (int i = 0; i < kItems; ++i) ASSERT_EQ(sunk[size_t(i)], i) << "threads " << threads;
    EXPECT_LE(most_in_flight.load(), int(kTokens));
    EXPECT_LE(c.most(), std::min(threads, int(kTokens)));
    if (threads > 1 && std::thread::hardware_concurrency() > 1) {
      EXPECT_GE(c.most(), 2);
    }
  }
}

TEST(Parallel, PipelineWithZeroThreadsFollowsTheLimit) {
  Concurrency c;
  int next = 0;
  WithThreadLimit(2, [&] {
    RunPipeline<Item>(
        0, 8,
        [&](Item& it) {
          if (next == 50) return false;
          it.index = next++;
          return true;
        },
        [&](Item&) {
          c.Enter();
          c.Leave();
        },
        [&](Item&) {});
  });
  EXPECT_EQ(next, 50);
  EXPECT_LE(c.most(), 2);
}

TEST(Parallel, PipelineRethrowsFromEveryStage) {
  for (int stage = 0; stage < 3; ++stage) {
    int made = 0;
    std::atomic<int> sunk{0};
    try {
      RunPipeline<Item>(
          2, 4,
          [&](Item& it) {
            if (stage == 0 && made == 5) throw std::runtime_error("source");
            it.index = made++;
            return made < 100000;
          },
          [&](Item& it) {
            if (stage == 1 && it.index == 5) throw std::runtime_error("work");
          },
          [&](Item& it) {
            if (stage == 2 && it.index == 5) throw std::runtime_error("sink");
            ++sunk;
          });
      ADD_FAILURE() << "stage " << stage << ": no exception";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), stage == 0 ? "source" : stage == 1 ? "work" : "sink");
    }
    EXPECT_LT(made, 100000) << "stage " << stage << ": the source went on";
    EXPECT_LE(sunk.load(), 5) << "stage " << stage;  // items after the failed one not sunk
  }
}

TEST(Parallel, PipelineStopsWhenTheSourceSaysSo) {
  int calls = 0;
  RunPipeline<Item>(
      2, 4,
      [&](Item&) {
        ++calls;
        return false;
      },
      [&](Item&) { FAIL() << "work without an item"; }, [&](Item&) { FAIL() << "sink"; });
  EXPECT_EQ(calls, 1);  // not asked again after it said no
}

}  // namespace
}  // namespace vox

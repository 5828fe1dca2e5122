// The page cache and the store's brick cache: budget, LRU eviction, pins
// surviving eviction, and single-flight loading under many threads.
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <cstring>
#include <functional>
#include <fstream>
#include <iterator>
#include <latch>
#include <string>
#include <thread>
#include <vector>

#include "core/util/memory_budget.h"
#include "storage/page_cache.h"
#include "storage/store.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using Cache = PageCache<int>;

StatusOr<std::pair<Cache::Value, size_t>> Make(int v, size_t charge) {
  return std::make_pair(std::make_shared<const int>(v), charge);
}

// Waits until thread `tid` of this process sleeps in the kernel (state S in
// /proc/self/task/TID/stat). A thread that has published its id and then
// calls GetOrLoad on a key being loaded or claimed can sleep only on the
// cache's condition variable (its mutex is free: no other thread holds it
// for long), so this orders "the asker waits" before what follows by an
// event, not by a delay.
void WaitUntilAsleep(pid_t tid) {
  const std::string path = "/proc/self/task/" + std::to_string(tid) + "/stat";
  for (;;) {
    std::ifstream in(path);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const size_t paren = text.rfind(')');  // the name may hold spaces; the state follows it
    if (paren != std::string::npos && paren + 2 < text.size() && text[paren + 2] == 'S') return;
    std::this_thread::yield();
  }
}

// Starts `ask` on a new thread and returns once that thread sleeps in it.
std::thread StartAsleep(std::function<void()> ask) {
  std::atomic<pid_t> tid{0};
  std::thread t([&tid, ask = std::move(ask)] {
    tid = gettid();
    ask();
  });
  while (tid == 0) std::this_thread::yield();
  WaitUntilAsleep(tid);
  return t;
}

TEST(PageCache, LruEvictionWithinBudget) {
  Cache c(100);
  for (int k = 0; k < 4; ++k) ASSERT_TRUE(c.GetOrLoad(k, [&] { return Make(k, 30); }).ok());
  // 4 x 30 > 100: key 0 (least recently used) went.
  EXPECT_EQ(c.TotalCharge(), 90u);
  EXPECT_EQ(c.counters().evictions, 1u);
  EXPECT_EQ(c.Lookup(0), nullptr);
  // Touch 1, insert 4: now 2 is the oldest and goes.
  EXPECT_NE(c.Lookup(1), nullptr);
  ASSERT_TRUE(c.GetOrLoad(4, [&] { return Make(4, 30); }).ok());
  EXPECT_EQ(c.Lookup(2), nullptr);
  EXPECT_NE(c.Lookup(1), nullptr);
  EXPECT_NE(c.Lookup(3), nullptr);
  EXPECT_NE(c.Lookup(4), nullptr);
  EXPECT_LE(c.TotalCharge(), 100u);
  EXPECT_EQ(c.counters().evictions, 2u);
}

TEST(PageCache, PinnedValueSurvivesEviction) {
  Cache c(10);
  auto v = c.GetOrLoad(7, [] { return Make(77, 8); });
  ASSERT_TRUE(v.ok());
  Cache::Value pin = *v;
  ASSERT_TRUE(c.GetOrLoad(8, [] { return Make(88, 8); }).ok());  // evicts 7
  EXPECT_EQ(c.Lookup(7), nullptr);
  EXPECT_EQ(*pin, 77);  // still valid
  // An entry larger than the whole budget is returned, then not kept.
  auto big = c.GetOrLoad(9, [] { return Make(99, 1000); });
  ASSERT_TRUE(big.ok());
  EXPECT_EQ(**big, 99);
  EXPECT_LE(c.TotalCharge(), 10u);
}

TEST(PageCache, FailedLoadIsNotCachedAndReachesWaiters) {
  Cache c(100);
  int calls = 0;
  auto r = c.GetOrLoad(1, [&]() -> StatusOr<std::pair<Cache::Value, size_t>> {
    ++calls;
    return IoError("boom");
  });
  EXPECT_EQ(r.status().code(), StatusCode::kIoError);
  auto r2 = c.GetOrLoad(1, [&] {
    ++calls;
    return Make(1, 1);
  });
  EXPECT_TRUE(r2.ok());
  EXPECT_EQ(calls, 2);
}

TEST(PageCache, SingleFlightUnderManyThreads) {
  Cache c(1 << 20);
  std::atomic<int> loads{0};
  constexpr int kKeys = 16;
  std::vector<std::thread> threads;
  std::atomic<bool> go{false};
  std::atomic<int> bad{0};
  for (int t = 0; t < 32; ++t)
    threads.emplace_back([&, t] {
      while (!go) std::this_thread::yield();
      for (int i = 0; i < kKeys; ++i) {
        int k = (i + t) % kKeys;
        auto v = c.GetOrLoad(k, [&] {
          ++loads;
          return Make(k * 10, 100);
        });
        if (!v.ok() || **v != k * 10) ++bad;
      }
    });
  go = true;
  for (auto& th : threads) th.join();
  EXPECT_EQ(bad.load(), 0);
  EXPECT_EQ(loads.load(), kKeys);
  PageCacheCounters cc = c.counters();
  EXPECT_EQ(cc.misses, uint64_t(kKeys));
  EXPECT_EQ(cc.hits, uint64_t(32 * kKeys - kKeys));
}

// An ask for a key whose load is running waits for that load and shares its
// value, counted as joined. The order is made, not hoped for: the load
// blocks until the second asker sleeps in GetOrLoad.
TEST(PageCache, AnAskDuringALoadJoinsIt) {
  Cache c(100);
  std::latch loading(1), release(1);
  std::atomic<int> loads{0};
  std::thread first([&] {
    auto v = c.GetOrLoad(7, [&] {
      ++loads;
      loading.count_down();
      release.wait();
      return Make(70, 10);
    });
    ASSERT_TRUE(v.ok());
    EXPECT_EQ(**v, 70);
  });
  loading.wait();
  std::thread second = StartAsleep([&] {
    auto v = c.GetOrLoad(7, [&] {
      ++loads;
      return Make(-1, 10);
    });
    ASSERT_TRUE(v.ok());
    EXPECT_EQ(**v, 70);
  });
  release.count_down();
  first.join();
  second.join();
  EXPECT_EQ(loads.load(), 1);
  const PageCacheCounters cc = c.counters();
  EXPECT_EQ(cc.misses, 1u);
  EXPECT_EQ(cc.hits, 1u);
  EXPECT_EQ(cc.joined, 1u);
}

// A claim (a prefetch reading many values at once) makes askers wait for it;
// a claim finished with a value serves them, one finished without lets them
// load the value themselves. Peek never loads and counts no miss.
TEST(PageCache, ClaimsMakeAskersWaitAndReleaseThem) {
  Cache c(100);
  EXPECT_EQ(c.Peek(1), nullptr);
  EXPECT_EQ(c.counters().misses, 0u);
  ASSERT_TRUE(c.Claim(1));
  EXPECT_FALSE(c.Claim(1));  // claimed already
  EXPECT_TRUE(c.Contains(1));
  std::atomic<bool> loaded{false};
  // The asker waits on the claim (asleep in GetOrLoad; it cannot have
  // loaded: the claim is held).
  std::thread asker = StartAsleep([&] {
    auto v = c.GetOrLoad(1, [&] {
      loaded = true;
      return Make(-1, 10);
    });
    ASSERT_TRUE(v.ok());
    EXPECT_EQ(**v, 11);
  });
  EXPECT_FALSE(loaded.load());
  c.FinishClaim(1, std::make_shared<const int>(11), 10);
  asker.join();
  EXPECT_FALSE(loaded.load());
  EXPECT_EQ(c.counters().joined, 1u);  // it waited for the claim
  EXPECT_EQ(c.counters().prefetched, 1u);
  EXPECT_EQ(c.counters().prefetch_hits, 1u);  // it had a waiter
  EXPECT_EQ(c.counters().prefetch_unused, 0u);

  // Released without a value: the waiter loads it itself.
  ASSERT_TRUE(c.Claim(2));
  const uint64_t misses = c.counters().misses;
  std::thread asker2 = StartAsleep([&] {
    auto v = c.GetOrLoad(2, [&] { return Make(22, 10); });
    ASSERT_TRUE(v.ok());
    EXPECT_EQ(**v, 22);
  });
  c.FinishClaim(2, nullptr, 0);
  asker2.join();
  EXPECT_EQ(*c.Peek(2), 22);
  EXPECT_EQ(c.counters().misses, misses + 1);  // it loaded the value itself
  EXPECT_EQ(c.counters().joined, 1u);

  // Nobody waiting: cached as prefetched until first asked for.
  ASSERT_TRUE(c.Claim(3));
  c.FinishClaim(3, std::make_shared<const int>(33), 10);
  EXPECT_EQ(c.counters().prefetch_unused, 10u);
  EXPECT_EQ(*c.Peek(3), 33);
  EXPECT_EQ(c.counters().prefetch_unused, 0u);
  EXPECT_EQ(c.counters().prefetch_hits, 2u);
  EXPECT_FALSE(c.Claim(3));  // cached
}

TEST(ShardedPageCache, BudgetAcrossShardsAndSingleFlight) {
  ShardedPageCache<int> c(1000, 8);
  EXPECT_EQ(c.num_shards(), 8u);
  for (int k = 0; k < 500; ++k) {
    ASSERT_TRUE(c.GetOrLoad(k, [&] { return Make(k, 10); }).ok());
    ASSERT_LE(c.TotalCharge(), 1000u);
  }
  PageCacheCounters cc = c.counters();
  EXPECT_EQ(cc.misses, 500u);
  EXPECT_EQ(cc.evictions, 500u - cc.entries);
  EXPECT_GT(cc.entries, 50u);  // the shards together hold most of the budget
  EXPECT_EQ(cc.capacity, 1000u);
  // Automatic shard count: at least min_shard_bytes each, at most 16.
  EXPECT_EQ(ShardedPageCache<int>(3 << 20).num_shards(), 1u);
  EXPECT_EQ(ShardedPageCache<int>(40 << 20).num_shards(), 10u);
  EXPECT_EQ(ShardedPageCache<int>(size_t(1) << 32).num_shards(), 16u);
  // Single flight across threads still holds per key.
  ShardedPageCache<int> d(1 << 20, 4);
  std::atomic<int> loads{0};
  std::vector<std::thread> ts;
  for (int t = 0; t < 16; ++t)
    ts.emplace_back([&] {
      for (int k = 0; k < 32; ++k)
        (void)d.GetOrLoad(k, [&] {
          ++loads;
          return Make(k, 10);
        });
    });
  for (auto& t : ts) t.join();
  EXPECT_EQ(loads.load(), 32);
}

class StoreCache : public ::testing::Test {
 protected:
  void SetUp() override {
    auto vol = GenerateShape("sphere:128");
    ASSERT_TRUE(vol.ok());
    voxels_ = vol->voxels;
    meta_ = storage_test::MetaFor(vol->levels, 4, GridClass::kLevelSet, true);
    ASSERT_TRUE(storage_test::WriteVoxels(dir_ / "s", voxels_, meta_).ok());
  }
  storage_test::TempDir dir_;
  std::vector<LeafPoint> voxels_;
  StoreMeta meta_;
};

TEST_F(StoreCache, BudgetRespectedAndEvictionsCounted) {
  auto probe = Store::Open(dir_ / "s", {});
  ASSERT_TRUE(probe.ok());
  const uint32_t bricks = uint32_t((*probe)->meta().brick_count);
  ASSERT_GT(bricks, 40u);
  // All bricks in the cache, then a budget of a quarter of that.
  for (uint32_t id = 0; id < bricks; ++id) ASSERT_TRUE((*probe)->FetchBrick(id).ok());
  const uint64_t all = (*probe)->cache_stats().bytes_resident;
  ASSERT_GT(all, 0u);

  OpenOptions oo;
  oo.cache_bytes = all / 4;
  auto s = Store::Open(dir_ / "s", oo);
  ASSERT_TRUE(s.ok());
  uint64_t max_resident = 0;
  for (int pass = 0; pass < 2; ++pass)
    for (uint32_t id = 0; id < bricks; ++id) {
      auto b = (*s)->FetchBrick(id);
      ASSERT_TRUE(b.ok()) << b.status().ToString();
      max_resident = std::max(max_resident, (*s)->cache_stats().bytes_resident);
    }
  CacheStats cs = (*s)->cache_stats();
  EXPECT_LE(max_resident, oo.cache_bytes);
  EXPECT_EQ(cs.capacity, oo.cache_bytes);
  // A cyclic scan larger than the cache misses every time under LRU.
  EXPECT_EQ(cs.misses, 2u * bricks);
  EXPECT_EQ(cs.hits, 0u);
  EXPECT_GE(cs.evictions, 2u * bricks - bricks / 2);
  EXPECT_GT(cs.bytes_decompressed, 0u);
  EXPECT_GT(cs.brick_file_bytes, 0u);

  // Repeated fetches of one brick hit.
  ASSERT_TRUE((*s)->FetchBrick(3).ok());
  ASSERT_TRUE((*s)->FetchBrick(3).ok());
  EXPECT_EQ((*s)->cache_stats().hits, 1u);
}

TEST(HeapWatch, GivesUpOnlyGrowthPastTheTargetAndTheHighestReadingAnswered) {
  HeapWatch w;
  EXPECT_EQ(w.Absorb(100), 0u);  // no target: no watch
  w.SetTarget(100);
  EXPECT_EQ(w.Absorb(90), 0u);
  EXPECT_EQ(w.Absorb(100), 0u);
  EXPECT_EQ(w.Absorb(130), 30u);  // past the target
  EXPECT_EQ(w.Absorb(120), 0u);   // the cache given up left holes; not growth
  EXPECT_EQ(w.Absorb(130), 0u);
  EXPECT_EQ(w.Absorb(135), 5u);   // growth past the highest reading answered
  EXPECT_EQ(w.given_up(), 35u);
  w.SetTarget(200);  // a new target forgets what was answered
  EXPECT_EQ(w.given_up(), 0u);
  EXPECT_EQ(w.Absorb(150), 0u);
  EXPECT_EQ(w.Absorb(210), 10u);
  w.SetTarget(0);
  EXPECT_EQ(w.Absorb(1000), 0u);
}

TEST(HeapWatch, ReadsTheAnonymousMemoryOncePerCheckBytesLoaded) {
  HeapWatch w;
  w.SetTarget(1);  // every reading is growth past it: Loaded returns the reading - 1
  EXPECT_EQ(w.Loaded(HeapWatch::kCheckBytes / 2), 0u);
  const uint64_t anon = w.Loaded(HeapWatch::kCheckBytes / 2) + 1;
  EXPECT_GT(anon, uint64_t(1) << 20) << "a test process holds more than 1 MiB of its own";
  EXPECT_LT(anon, uint64_t(64) << 30);
  EXPECT_EQ(w.Loaded(1), 0u);  // the next check is kCheckBytes on
}

TEST_F(StoreCache, GivesCacheUpWhenTheHeapGrowsPastTheTarget) {
  auto probe = Store::Open(dir_ / "s", {});
  ASSERT_TRUE(probe.ok());
  const uint32_t bricks = uint32_t((*probe)->meta().brick_count);
  for (uint32_t id = 0; id < bricks; ++id) ASSERT_TRUE((*probe)->FetchBrick(id).ok());
  const uint64_t all = (*probe)->cache_stats().bytes_resident;
  OpenOptions oo;
  oo.cache_bytes = all / 2;  // a cyclic scan misses every time: it loads `all` per pass
  oo.read_windows = false;   // the capacity is the brick cache's alone
  auto s = Store::Open(dir_ / "s", oo);
  ASSERT_TRUE(s.ok());
  // A target of one byte: the first check (kCheckBytes loaded in the
  // process) finds the heap past it, and the store gives up its cache down
  // to a quarter of what it was given, never failing a fetch.
  struct Reset {
    ~Reset() { HeapWatch::Process().SetTarget(0); }
  } reset;
  HeapWatch::Process().SetTarget(1);
  int passes = 0;
  while ((*s)->cache_stats().given_to_heap == 0 && passes < 4 * int(HeapWatch::kCheckBytes / all) + 4) {
    for (uint32_t id = 0; id < bricks; ++id) ASSERT_TRUE((*s)->FetchBrick(id).ok());
    ++passes;
  }
  const CacheStats cs = (*s)->cache_stats();
  EXPECT_EQ(cs.given_to_heap, oo.cache_bytes - oo.cache_bytes / 4);
  EXPECT_EQ(cs.capacity, oo.cache_bytes / 4);
  for (uint32_t id = 0; id < bricks; ++id) ASSERT_TRUE((*s)->FetchBrick(id).ok());
  EXPECT_LE((*s)->cache_stats().bytes_resident, oo.cache_bytes / 4);
  EXPECT_GT(HeapWatch::Process().given_up(), 0u);
}

TEST_F(StoreCache, PinsSurviveEviction) {
  OpenOptions oo;
  oo.cache_bytes = 1;  // everything is evicted at once
  auto s = Store::Open(dir_ / "s", oo);
  ASSERT_TRUE(s.ok());
  auto ref = Store::Open(dir_ / "s", {});
  ASSERT_TRUE(ref.ok());
  auto b0 = (*s)->FetchBrick(0);
  ASSERT_TRUE(b0.ok());
  for (uint32_t id = 1; id < 20; ++id) ASSERT_TRUE((*s)->FetchBrick(id).ok());
  EXPECT_EQ((*s)->cache_stats().bytes_resident, 0u);
  auto r0 = (*ref)->FetchBrick(0);
  ASSERT_TRUE(r0.ok());
  ASSERT_EQ(b0->num_cells, r0->num_cells);
  EXPECT_EQ(0, std::memcmp(b0->cells, r0->cells, sizeof(CompactCell) * b0->num_cells));
}

TEST_F(StoreCache, SingleFlightUnderManyThreads) {
  auto s = Store::Open(dir_ / "s", {});
  ASSERT_TRUE(s.ok());
  const uint32_t bricks = uint32_t((*s)->meta().brick_count);
  std::atomic<int> bad{0};
  // 16 threads released together ask for the same few bricks at once, then
  // all. (Plain threads: a TBB parallel_for of short tasks may run on one or
  // two threads of a busy machine, and then nothing races.)
  constexpr int kThreads = 16, kTasks = 4000;
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      while (!go) std::this_thread::yield();
      for (int i = t; i < kTasks; i += kThreads) {
        uint32_t id = i < kTasks / 2 ? uint32_t(i % 4) : uint32_t(i % bricks);
        auto b = (*s)->FetchBrick(id);
        auto a = (*s)->Attributes(id, 0);
        if (!b.ok() || !a.ok() || b->num_cells == 0) ++bad;
      }
    });
  go = true;
  for (auto& th : threads) th.join();
  EXPECT_EQ(bad.load(), 0);
  CacheStats cs = (*s)->cache_stats();
  EXPECT_EQ(cs.misses, bricks);  // one decompression per brick
  EXPECT_EQ(cs.hits + cs.misses, 8000u);
  EXPECT_EQ(cs.evictions, 0u);
}

}  // namespace
}  // namespace vox

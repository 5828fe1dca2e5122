// BufferPool: blocks never overlap and stay inside the mapping, the bytes in
// use are exact, and after any churn freeing everything merges the pool back
// into its first blocks (a whole-pool allocation succeeds again), so the
// pool's free space cannot splinter for good. Against a model of the live
// blocks, independent of the allocator's lists.
#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <random>
#include <thread>
#include <vector>

#include "storage/buffer_pool.h"
#include "storage/page_cache.h"

namespace vox {
namespace {

TEST(BufferPool, BlockSizesArePowersOfTwoFrom512) {
  EXPECT_EQ(BufferPool::BlockSize(1), 512u);
  EXPECT_EQ(BufferPool::BlockSize(512), 512u);
  EXPECT_EQ(BufferPool::BlockSize(513), 1024u);
  EXPECT_EQ(BufferPool::BlockSize(20720), 32768u);
}

TEST(BufferPool, ChurnKeepsBlocksApartAndMergesBackWhenAllAreFree) {
  const uint64_t size = (uint64_t(12) << 20) + 3 * 512;  // not a power of two: a tail of small blocks
  auto pool = BufferPool::Create(size);
  ASSERT_TRUE(pool.ok()) << pool.status().ToString();
  BufferPool& p = **pool;
  ASSERT_EQ(p.capacity(), size);
  const uintptr_t lo = reinterpret_cast<uintptr_t>(p.base());
  std::map<uintptr_t, size_t> live;  // start -> block size
  std::mt19937_64 rng(7);
  uint64_t in_use = 0, failed = 0;
  for (int step = 0; step < 200000; ++step) {
    if (live.empty() || rng() % 2 == 0) {
      const size_t n = 1 + rng() % (rng() % 8 == 0 ? 300000 : 20000);
      void* b = p.Allocate(n);
      if (b == nullptr) {
        ++failed;
        continue;
      }
      const uintptr_t a = reinterpret_cast<uintptr_t>(b);
      const size_t bs = BufferPool::BlockSize(n);
      ASSERT_TRUE(p.Owns(b));
      ASSERT_EQ((a - lo) % bs, 0u) << "a block lies at a multiple of its size";
      ASSERT_LE(a + bs, lo + size);
      auto next = live.lower_bound(a);
      if (next != live.end()) ASSERT_LE(a + bs, next->first) << "overlaps the next block";
      if (next != live.begin()) {
        auto prev = std::prev(next);
        ASSERT_LE(prev->first + prev->second, a) << "overlaps the previous block";
      }
      std::memset(b, 0xab, std::min<size_t>(bs, 64));  // the links of free blocks must not be live data
      live[a] = bs;
      in_use += bs;
    } else {
      auto it = live.begin();
      std::advance(it, rng() % live.size());
      p.Free(reinterpret_cast<void*>(it->first));
      in_use -= it->second;
      live.erase(it);
    }
    ASSERT_EQ(p.in_use(), in_use);
  }
  EXPECT_GT(failed, 0u) << "the churn should fill the pool at times";
  for (auto& [a, bs] : live) p.Free(reinterpret_cast<void*>(a));
  EXPECT_EQ(p.in_use(), 0u);
  EXPECT_LE(p.peak_in_use(), size);
  // Merged back: the largest block (8 MiB) and the rest are whole again.
  void* big = p.Allocate(uint64_t(8) << 20);
  ASSERT_NE(big, nullptr);
  void* second = p.Allocate(uint64_t(4) << 20);
  ASSERT_NE(second, nullptr);
  EXPECT_EQ(p.Allocate(4096), nullptr) << "only the 1.5 KiB tail is left";
  EXPECT_NE(p.Allocate(1024), nullptr);
  EXPECT_NE(p.Allocate(512), nullptr);
  EXPECT_EQ(p.Allocate(1), nullptr);
}

TEST(BufferPool, ThreadsChurningTogetherLeaveItWhole) {
  auto pool = BufferPool::Create(uint64_t(8) << 20);
  ASSERT_TRUE(pool.ok());
  BufferPool& p = **pool;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&p, t] {
      std::mt19937 rng(t);
      std::vector<void*> mine;
      for (int i = 0; i < 50000; ++i) {
        if (mine.size() < 64 && rng() % 3 != 0) {
          if (void* b = p.Allocate(1 + rng() % 30000)) {
            std::memset(b, t, 16);
            mine.push_back(b);
          }
        } else if (!mine.empty()) {
          p.Free(mine.back());
          mine.pop_back();
        }
      }
      for (void* b : mine) p.Free(b);
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(p.in_use(), 0u);
  EXPECT_NE(p.Allocate(uint64_t(8) << 20), nullptr);
}

TEST(BrickPool, BricksComeFromThePoolOnceReservedAndFromTheHeapWhenItIsFull) {
  ASSERT_TRUE(ReserveBrickPool(uint64_t(1) << 20).ok());
  const BrickPoolStats before = ReadBrickPoolStats();
  EXPECT_EQ(before.capacity, uint64_t(1) << 20);
  void* a = BrickAllocate(600 << 10);  // a 1 MiB block: the whole pool
  EXPECT_EQ(BrickBlockBytes(a, 600 << 10), size_t(1) << 20);
  void* b = BrickAllocate(1000);  // no room: the heap
  EXPECT_EQ(BrickBlockBytes(b, 1000), 1000u);
  const BrickPoolStats during = ReadBrickPoolStats();
  EXPECT_EQ(during.in_use, uint64_t(1) << 20);
  EXPECT_EQ(during.overflows, before.overflows + 1);
  // A pool of another size is not mapped while a block is live.
  ASSERT_TRUE(ReserveBrickPool(uint64_t(2) << 20).ok());
  EXPECT_EQ(ReadBrickPoolStats().capacity, uint64_t(1) << 20);
  BrickFree(a);
  BrickFree(b);
  ASSERT_TRUE(ReserveBrickPool(uint64_t(2) << 20).ok());
  EXPECT_EQ(ReadBrickPoolStats().capacity, uint64_t(2) << 20);
  EXPECT_EQ(ReadBrickPoolStats().in_use, 0u);
}

// A cached value whose bytes come from the brick pool, as a decoded brick's do.
struct Blob {
  explicit Blob(size_t n) : bytes(n) {}
  std::vector<uint8_t, BrickAllocator<uint8_t>> bytes;
};

// A cache (far larger than the pool, so it never evicts on its own) whose
// blobs fill the pool: 8 blocks of 32 KiB, inserted 0..7, 0 the least
// recently used.
struct FullPool {
  static constexpr size_t kBlob = 32 << 10;
  PageCache<Blob> cache{size_t(1) << 30};
  uint64_t id = 0;
  FullPool() {
    EXPECT_TRUE(ReserveBrickPool(8 * kBlob).ok());
    EXPECT_EQ(ReadBrickPoolStats().capacity, 8 * kBlob);
    for (uint64_t k = 0; k < 8; ++k) cache.Insert(k, std::make_shared<const Blob>(kBlob), kBlob);
    EXPECT_EQ(ReadBrickPoolStats().in_use, 8 * kBlob);
    id = RegisterBrickReclaimer([this] { return uint64_t(cache.EvictUnpinned()); });
  }
  ~FullPool() { UnregisterBrickReclaimer(id); }
};

TEST(BrickPool, AFullPoolEvictsUnpinnedBricksBeforeGoingToTheHeap) {
  FullPool f;
  // Pins on 0 and 2: the evictions must skip them, so the first 64 KiB block
  // that can merge back is 4+5, after 1, 3, 4 and 5 (in LRU order) are gone.
  auto pin0 = f.cache.Peek(0), pin2 = f.cache.Peek(2);
  const BrickPoolStats before = ReadBrickPoolStats();
  {
    Blob big(2 * FullPool::kBlob);
    // From the pool: a block of the pool's size class.
    EXPECT_EQ(BrickBlockBytes(big.bytes.data(), big.bytes.size()), 2 * FullPool::kBlob);
    const BrickPoolStats after = ReadBrickPoolStats();
    EXPECT_EQ(after.overflows, before.overflows);
    EXPECT_EQ(after.reclaimed, before.reclaimed + 4);
    EXPECT_EQ(after.reclaimed_bytes, before.reclaimed_bytes + 4 * FullPool::kBlob);
    for (uint64_t k : {0, 2, 6, 7}) EXPECT_TRUE(f.cache.Contains(k)) << k;
    for (uint64_t k : {1, 3, 4, 5}) EXPECT_FALSE(f.cache.Contains(k)) << k;
    EXPECT_EQ(f.cache.counters().evictions, 4u);
    EXPECT_EQ(pin0->bytes.size(), FullPool::kBlob);  // the pinned blobs are whole
    EXPECT_EQ(pin2->bytes.size(), FullPool::kBlob);
  }
  pin0.reset();
  pin2.reset();
  f.cache.SetCapacity(0);
  EXPECT_EQ(ReadBrickPoolStats().in_use, 0u);
}

TEST(BrickPool, AllPinnedGoesToTheHeapAndEvictsNothing) {
  FullPool f;
  std::vector<std::shared_ptr<const Blob>> pins;
  for (uint64_t k = 0; k < 8; ++k) pins.push_back(f.cache.Peek(k));
  const BrickPoolStats before = ReadBrickPoolStats();
  {
    Blob more(1000);
    EXPECT_EQ(BrickBlockBytes(more.bytes.data(), more.bytes.size()), 1000u);  // from the heap
    const BrickPoolStats after = ReadBrickPoolStats();
    EXPECT_EQ(after.overflows, before.overflows + 1);
    EXPECT_EQ(after.reclaimed, before.reclaimed);
    EXPECT_EQ(f.cache.counters().entries, 8u);
  }
  pins.clear();
  f.cache.SetCapacity(0);
  EXPECT_EQ(ReadBrickPoolStats().in_use, 0u);
}

}  // namespace
}  // namespace vox

// The brick cache under stress: many threads fetching random bricks and
// prefetching random lists through a tiny budget, while every seventh read
// of the brick file fails. Every fetch either returns exactly the brick a
// clean store returns, or the injected IoError naming the file; a failure is
// never cached; the budget holds. Run under TSan by scripts/sanitize.sh.
#include <gtest/gtest.h>

#include <atomic>
#include <random>
#include <thread>
#include <vector>

#include "core/util/file.h"
#include "storage/internal/store_impl.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

TEST(CacheStress, ManyThreadsTinyBudgetInjectedFailures) {
  storage_test::TempDir tmp;
  auto vol = GenerateShape("sphere:96");
  ASSERT_TRUE(vol.ok());
  const StoreMeta meta = storage_test::MetaFor(vol->levels, vol->levels - 3, GridClass::kLevelSet, true);
  const std::string dir = tmp / "s";
  ASSERT_TRUE(storage_test::WriteVoxels(dir, vol->voxels, meta).ok());

  // The truth: every brick's cells from a clean store.
  auto clean = Store::Open(dir, {});
  ASSERT_TRUE(clean.ok());
  const uint32_t bricks = uint32_t((*clean)->meta().brick_count);
  ASSERT_GT(bricks, 50u);
  std::vector<std::vector<uint32_t>> truth(bricks);
  for (uint32_t id = 0; id < bricks; ++id) {
    auto b = (*clean)->FetchBrick(id);
    ASSERT_TRUE(b.ok());
    for (uint32_t i = 0; i < b->num_cells; ++i) truth[id].push_back(b->cells[i].bits);
  }

  auto index = OpenPreadFile(dir + "/index.vxi");
  auto brick_file = OpenPreadFile(dir + "/bricks.vxb");
  ASSERT_TRUE(index.ok() && brick_file.ok());
  auto faulty = std::make_unique<FaultInjectionFile>(std::move(*brick_file));
  FaultInjectionFile* fault = faulty.get();
  OpenOptions oo;
  oo.cache_bytes = 24 << 10;  // a handful of bricks
  auto store = storage_internal::OpenStoreFromFiles(dir, std::move(*index), std::move(faulty), oo);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  fault->FailEveryNthRead(7);

  constexpr int kThreads = 12, kFetches = 1500;
  std::atomic<uint64_t> good{0}, failed{0}, wrong{0}, bad_errors{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      std::mt19937 rng(1234 + t);
      std::vector<BrickView> held;  // pins kept a while: eviction must not free them
      for (int i = 0; i < kFetches; ++i) {
        const uint32_t id = rng() % bricks;
        if (i % 97 == 0) {
          std::vector<uint32_t> ids;
          for (int k = 0; k < 8; ++k) ids.push_back(rng() % (bricks + 4));  // some unknown
          (*store)->Prefetch(ids);
        }
        if (i % 389 == 0) (*store)->CancelPrefetch();
        auto b = (*store)->FetchBrick(id);
        if (!b.ok()) {
          ++failed;
          if (b.status().code() != StatusCode::kIoError ||
              b.status().message().find("injected read error") == std::string::npos ||
              b.status().message().find("bricks.vxb") == std::string::npos)
            ++bad_errors;
          continue;
        }
        bool same = b->num_cells == truth[id].size();
        for (uint32_t c = 0; same && c < b->num_cells; ++c) same = b->cells[c].bits == truth[id][c];
        if (!same) ++wrong;
        ++good;
        held.push_back(*b);
        if (held.size() > 3) held.erase(held.begin());
        for (const BrickView& h : held)  // pinned bricks stay readable
          if (h.num_cells == 0 || h.cells == nullptr) ++wrong;
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(wrong.load(), 0u);
  EXPECT_EQ(bad_errors.load(), 0u);
  EXPECT_GT(good.load(), uint64_t(kThreads * kFetches) / 2);
  EXPECT_GT(failed.load(), 0u);
  EXPECT_GT(fault->injected_failures(), 0u);
  const CacheStats cs = (*store)->cache_stats();
  EXPECT_LE(cs.bytes_resident, oo.cache_bytes);
  EXPECT_GT(cs.evictions, 0u);

  // Failures were not cached: with faults off, every brick reads back right.
  fault->FailEveryNthRead(0);
  for (uint32_t id = 0; id < bricks; ++id) {
    auto b = (*store)->FetchBrick(id);
    ASSERT_TRUE(b.ok()) << id << ": " << b.status().ToString();
    ASSERT_EQ(b->num_cells, truth[id].size());
  }
}

}  // namespace
}  // namespace vox

// Long: a sphere:1024 store (4 M voxels) traced from many threads with a
// cache a tenth of its bricks, against MemoryOctree on the same voxels for
// several splits; the budget holds throughout. Label "long".
#include <gtest/gtest.h>

#include <atomic>
#include <random>

#include "core/tracer.h"
#include "core/util/parallel.h"
#include "storage/store_info.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

TEST(Large, Sphere1024TracesLikeMemoryUnderATightCache) {
  auto vol = GenerateShape("sphere:1024");
  ASSERT_TRUE(vol.ok());
  const int levels = vol->levels;
  StoreMeta meta = storage_test::MetaFor(levels, 5, GridClass::kLevelSet, false);
  storage_test::TempDir tmp;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp / "s", vol->voxels, meta).ok());
  auto info = InspectStore(tmp / "s", false);
  ASSERT_TRUE(info.ok());
  OpenOptions oo;
  oo.cache_bytes = info->decoded_bytes / 10;
  auto store = Store::Open(tmp / "s", oo);
  ASSERT_TRUE(store.ok());
  auto mem = MemoryOctree::Build(vol->voxels, levels, levels);
  ASSERT_TRUE(mem.ok());
  const double n = double(int64_t(1) << levels);
  std::vector<Ray> rays(20000);
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-0.2, 1.2), d(-1, 1);
  for (Ray& r : rays) {
    r.origin = glm::dvec3(u(rng), u(rng), u(rng)) * n;
    const LeafPoint& p = vol->voxels[rng() % vol->voxels.size()];
    r.dir = glm::dvec3(p.x + 0.5, p.y + 0.5, p.z + 0.5) - r.origin + glm::dvec3(d(rng), d(rng), d(rng));
  }
  for (int n1 : {3, 5, 7, 10}) {
    auto ts = Tracer<>::Create((*store)->view(), n1);
    auto tm = Tracer<>::Create((*mem)->view(), n1);
    ASSERT_TRUE(ts.ok() && tm.ok());
    std::atomic<int> mismatches{0}, errors{0}, hits{0};
    std::atomic<uint64_t> max_resident{0};
    auto trace = [&](size_t i) {
      auto a = ts->FirstHit(rays[i]);
      auto b = tm->FirstHit(rays[i]);
      if (!a.ok() || !b.ok()) {
        ++errors;
        return;
      }
      if (a->has_value() != b->has_value() ||
          (a->has_value() && ((*a)->voxel != (*b)->voxel || (*a)->t != (*b)->t)))
        ++mismatches;
      if (a->has_value()) {
        ++hits;
        if (!(*store)->Attributes((*a)->brick, (*a)->payload).ok()) ++errors;
      }
      uint64_t r = (*store)->cache_stats().bytes_resident;
      uint64_t m = max_resident.load();
      while (r > m && !max_resident.compare_exchange_weak(m, r)) {}
    };
    ParallelFor(0, rays.size(), 256, [&](size_t lo, size_t hi) {
      for (size_t i = lo; i < hi; ++i) trace(i);
    });
    EXPECT_EQ(errors.load(), 0) << "split " << n1;
    EXPECT_EQ(mismatches.load(), 0) << "split " << n1;
    EXPECT_GT(hits.load(), 10000) << "split " << n1;
    EXPECT_LE(max_resident.load(), oo.cache_bytes);
  }
  CacheStats cs = (*store)->cache_stats();
  EXPECT_GT(cs.evictions, 0u);
}

}  // namespace
}  // namespace vox

// The ingest's memory does not grow with its input like the input does:
// every C++ heap allocation of this test program is counted (operator new is
// replaced), and the peak heap of Ingest() on a level-set sphere 4 times the
// radius (16 times the leaves and file bytes) may grow by at most 25% of the
// file's growth (measured: 13%; the compact tables take about 45 bytes per
// leaf, where OpenVDB's delayed-load tree and per-leaf tables hold some
// 380 bytes per leaf, more than the file's own bytes per leaf). Counting allocations rather than RSS keeps the test
// exact on a loaded machine. A budget (--memory-mb) too small for the
// grid's tables is refused with an error naming the flag, and leaves no store.
#include <malloc.h>
#include <sys/stat.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/ingest.h"
#include "tests/ingest/ingest_test_util.h"

namespace {
std::atomic<int64_t> g_live{0}, g_peak{0};

void* Count(void* p) {
  if (!p) throw std::bad_alloc();
  const int64_t now = g_live.fetch_add(int64_t(malloc_usable_size(p))) +
                      int64_t(malloc_usable_size(p));
  int64_t peak = g_peak.load();
  while (now > peak && !g_peak.compare_exchange_weak(peak, now)) {
  }
  return p;
}
void Uncount(void* p) {
  if (!p) return;
  g_live.fetch_sub(int64_t(malloc_usable_size(p)));
  std::free(p);
}
}  // namespace

void* operator new(size_t n) { return Count(std::malloc(n ? n : 1)); }
void* operator new[](size_t n) { return Count(std::malloc(n ? n : 1)); }
void* operator new(size_t n, std::align_val_t a) {
  return Count(std::aligned_alloc(size_t(a), (n + size_t(a) - 1) / size_t(a) * size_t(a)));
}
void* operator new[](size_t n, std::align_val_t a) {
  return Count(std::aligned_alloc(size_t(a), (n + size_t(a) - 1) / size_t(a) * size_t(a)));
}
void operator delete(void* p) noexcept { Uncount(p); }
void operator delete[](void* p) noexcept { Uncount(p); }
void operator delete(void* p, size_t) noexcept { Uncount(p); }
void operator delete[](void* p, size_t) noexcept { Uncount(p); }
void operator delete(void* p, std::align_val_t) noexcept { Uncount(p); }
void operator delete[](void* p, std::align_val_t) noexcept { Uncount(p); }
void operator delete(void* p, size_t, std::align_val_t) noexcept { Uncount(p); }
void operator delete[](void* p, size_t, std::align_val_t) noexcept { Uncount(p); }

namespace vox {
namespace {

class IngestMemoryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  // Writes a sphere of `radius` voxels; returns its file size.
  uint64_t WriteSphere(const std::string& path, float radius) {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        radius, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
    g->setName("sphere");
    testutil::WriteVdb(path, {g});
    struct stat st;
    EXPECT_EQ(::stat(path.c_str(), &st), 0);
    return uint64_t(st.st_size);
  }

  // The peak heap above the heap before Ingest().
  int64_t PeakOfIngest(const std::string& vdb, const std::string& store) {
    IngestOptions o;
    o.input = vdb;
    o.output = store;
    o.threads = 2;
    o.lod = lod_;
    const int64_t before = g_live.load();
    g_peak.store(before);
    auto s = Ingest(o);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return g_peak.load() - before;
  }

  testutil::TempDir dir_;
  bool lod_ = false;  // the level-of-detail pyramid: measured apart (bounded, not growing)
};

TEST_F(IngestMemoryTest, PeakHeapGrowsFarSlowerThanTheFile) {
  const uint64_t small = WriteSphere(dir_.File("small.vdb"), 60.0f);
  const uint64_t large = WriteSphere(dir_.File("large.vdb"), 240.0f);
  // Warm-up: OpenVDB's registries and TBB's threads are allocated once.
  PeakOfIngest(dir_.File("small.vdb"), dir_.File("warm.store"));
  const int64_t p_small = PeakOfIngest(dir_.File("small.vdb"), dir_.File("small.store"));
  const int64_t p_large = PeakOfIngest(dir_.File("large.vdb"), dir_.File("large.store"));
  const double growth = double(p_large - p_small) / double(large - small);
  std::printf("file %llu -> %llu bytes, peak heap %lld -> %lld bytes: %.1f%% of the growth\n",
              (unsigned long long)small, (unsigned long long)large, (long long)p_small,
              (long long)p_large, 100 * growth);
  EXPECT_GT(large, 10 * small);
  EXPECT_LT(growth, 0.25);
  // The pyramid's pass adds its small brick cache, prefetches and one coarse
  // brick per level: a bounded amount, not the volume.
  lod_ = true;
  const int64_t p_large_lod = PeakOfIngest(dir_.File("large.vdb"), dir_.File("large-lod.store"));
  std::printf("with the pyramid: peak heap %lld bytes\n", (long long)p_large_lod);
  EXPECT_LT(p_large_lod - p_large, int64_t(12) << 20);
}

TEST_F(IngestMemoryTest, BudgetBelowTheTablesIsRefused) {
  WriteSphere(dir_.File("s.vdb"), 150.0f);
  IngestOptions o;
  o.input = dir_.File("s.vdb");
  o.output = dir_.File("s.store");
  o.memory_bytes = uint64_t(64) << 20;
  auto s = Ingest(o);
  // Its tables take a few MB: the ingest fits in 64 MiB.
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->memory_budget, o.memory_bytes);
  o.output = dir_.File("t.store");
  o.memory_bytes = uint64_t(1) << 20;
  s = Ingest(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().ToString().find("--memory-mb"), std::string::npos) << s.status().ToString();
  EXPECT_FALSE(std::filesystem::exists(o.output));
}

}  // namespace
}  // namespace vox

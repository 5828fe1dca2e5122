// vox-ingest of a raw array four times larger than the memory cgroup it runs
// in: the array is streamed into the store brick by brick, so it finishes
// with the store of every element above the threshold (counted here while
// the file is written), where a grid of the array in memory (about 4 bytes
// per element of every 8^3 block holding one above the threshold: all of
// them here, 1.5 GiB) would be killed by the cgroup's OOM killer. Needs root
// and a writable memory cgroup; skips otherwise.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "storage/sample.h"
#include "storage/store.h"
#include "tests/common/cgroup_util.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using vox::testing::CgroupRunOptions;
using vox::testing::ReadAll;
using vox::testing::RunInMemoryCgroup;

// A scattered byte per element: about 2% of them above 250.
uint8_t Element(int64_t i, int64_t j, int64_t k) {
  uint32_t h = uint32_t(i) * 73856093u ^ uint32_t(j) * 19349663u ^ uint32_t(k) * 83492791u;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  return uint8_t(h >> 24);
}

TEST(ArrayCgroupTest, RawArrayFourTimesTheLimit) {
  VOX_REQUIRE_MEMORY_CGROUP();
  testutil::TempDir dir;
  const int64_t nx = 384, ny = 1024, nz = 1024;  // 384 MiB of uint8
  const uint64_t limit = uint64_t(96) << 20;
  const std::string raw = dir.File("big.raw"), store = dir.File("big.store");
  uint64_t expected = 0;
  int64_t lo[3] = {nx, ny, nz}, hi[3] = {-1, -1, -1};
  {
    std::FILE* f = std::fopen(raw.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    std::vector<uint8_t> row(size_t(ny * nz));
    for (int64_t i = 0; i < nx; ++i) {
      for (int64_t j = 0; j < ny; ++j)
        for (int64_t k = 0; k < nz; ++k) {
          const uint8_t v = Element(i, j, k);
          row[size_t(j * nz + k)] = v;
          if (v <= 250) continue;
          ++expected;
          const int64_t c[3] = {i, j, k};
          for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
        }
      ASSERT_EQ(std::fwrite(row.data(), 1, row.size(), f), row.size());
    }
    ASSERT_EQ(std::fclose(f), 0);
  }
  ASSERT_GE(uint64_t(nx * ny * nz), 4 * limit);
  CgroupRunOptions o;
  o.limit_bytes = limit;
  o.stderr_path = dir.File("ingest.log");
  auto run = RunInMemoryCgroup({VOX_INGEST_BINARY, raw, store, "--shape", "384,1024,1024",
                                "--dtype", "uint8", "--threshold", "250", "--threads", "2"},
                               o);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  std::printf("a %lld MiB array in %llu MiB: %s\n", (long long)(nx * ny * nz >> 20),
              (unsigned long long)(limit >> 20), run->Describe().c_str());
  ASSERT_FALSE(run->oom_killed) << ReadAll(dir.File("ingest.log"));
  ASSERT_EQ(run->exit_code, 0) << run->Describe() << ReadAll(dir.File("ingest.log"));
  auto s = Store::Open(store, OpenOptions{});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->meta().voxel_count, expected);
  EXPECT_EQ((*s)->meta().bbox_min, glm::i64vec3(lo[0], lo[1], lo[2]));
  EXPECT_EQ((*s)->meta().bbox_max, glm::i64vec3(hi[0], hi[1], hi[2]));
  // A region's densities read back: the elements above the threshold, 0 elsewhere.
  auto values = StoreValues::Open(store, 0, uint64_t(64) << 20);
  ASSERT_TRUE(values.ok()) << values.status().ToString();
  const glm::i64vec3 rlo(100, 500, 0), rhi(108, 564, nz);
  std::vector<float> got(size_t(8 * 64 * nz));
  ASSERT_TRUE((*values)->Read(rlo, rhi, ValueAttr::kDensity, got.data()).ok());
  size_t n = 0, wrong = 0;
  for (int64_t i = rlo.x; i < rhi.x; ++i)
    for (int64_t j = rlo.y; j < rhi.y; ++j)
      for (int64_t k = rlo.z; k < rhi.z; ++k, ++n) {
        const uint8_t v = Element(i, j, k);
        wrong += got[n] != (v > 250 ? float(v) : 0.0f);
      }
  EXPECT_EQ(wrong, 0u) << "of " << n;
}

}  // namespace
}  // namespace vox

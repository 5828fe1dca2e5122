// The memory cgroup harness itself: a program allocating more than the limit
// is OOM-killed, one below it exits normally, the peak charge is reported,
// and the cgroup is gone afterwards.
#include "tests/common/cgroup_util.h"

#include <gtest/gtest.h>

#include <dirent.h>

#include <fstream>
#include <string>

namespace vox::testing {
namespace {

constexpr uint64_t kMiB = uint64_t(1) << 20;

// Names of this process's test cgroups left in the hierarchy (should be none).
int LeftoverCgroups() {
  cgroup_internal::Hierarchy h = cgroup_internal::FindHierarchy();
  int n = 0;
  DIR* d = ::opendir(h.mount.c_str());
  if (d == nullptr) return -1;
  const std::string prefix = "vox_test_" + std::to_string(::getpid()) + "_";
  while (dirent* e = ::readdir(d))
    if (std::string(e->d_name).rfind(prefix, 0) == 0) ++n;
  ::closedir(d);
  return n;
}

TEST(CgroupHarness, BelowTheLimitExitsNormally) {
  VOX_REQUIRE_MEMORY_CGROUP();
  CgroupRunOptions o;
  o.limit_bytes = 128 * kMiB;
  o.stdout_path = ::testing::TempDir() + "cgroup_alloc_out.txt";
  auto r = RunInMemoryCgroup({VOX_CGROUP_ALLOC_BIN, "32", "7"}, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->term_signal, 0) << r->Describe();
  EXPECT_EQ(r->exit_code, 7) << r->Describe();
  EXPECT_FALSE(r->oom_killed);
  EXPECT_EQ(r->failcnt, 0u);
  // 32 MiB touched: charged in full, and never more than the limit.
  EXPECT_GE(r->peak_bytes, 32 * kMiB) << r->Describe();
  EXPECT_LE(r->peak_bytes, 128 * kMiB) << r->Describe();
  std::ifstream out(o.stdout_path);
  std::string line;
  std::getline(out, line);
  EXPECT_EQ(line, "touched 32 MiB");
  EXPECT_EQ(LeftoverCgroups(), 0);
}

TEST(CgroupHarness, AboveTheLimitIsOomKilled) {
  VOX_REQUIRE_MEMORY_CGROUP();
  CgroupRunOptions o;
  o.limit_bytes = 48 * kMiB;
  auto r = RunInMemoryCgroup({VOX_CGROUP_ALLOC_BIN, "256"}, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->term_signal, SIGKILL) << r->Describe();
  EXPECT_TRUE(r->oom_killed) << r->Describe();
  EXPECT_GT(r->failcnt, 0u);
  // It reached the limit (within a few pages) and no further.
  EXPECT_GE(r->peak_bytes, 44 * kMiB) << r->Describe();
  EXPECT_LE(r->peak_bytes, 48 * kMiB) << r->Describe();
  EXPECT_EQ(LeftoverCgroups(), 0);
}

TEST(CgroupHarness, UnlimitedRunIsMeasured) {
  VOX_REQUIRE_MEMORY_CGROUP();
  CgroupRunOptions o;  // no limit
  o.drop_page_cache = true;
  auto small = RunInMemoryCgroup({VOX_CGROUP_ALLOC_BIN, "8"}, o);
  auto big = RunInMemoryCgroup({VOX_CGROUP_ALLOC_BIN, "200"}, o);
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  ASSERT_TRUE(big.ok()) << big.status().ToString();
  EXPECT_EQ(big->exit_code, 0) << big->Describe();
  EXPECT_FALSE(big->oom_killed);
  EXPECT_GE(big->peak_bytes, 200 * kMiB);
#ifndef VOX_SANITIZED  // ASan's shadow memory and allocator change what is charged
  // The peak follows the allocation: 192 MiB more touched, about 192 MiB more charged.
  const double diff = double(big->peak_bytes) - double(small->peak_bytes);
  EXPECT_GT(diff, 180.0 * kMiB) << small->Describe() << " / " << big->Describe();
  EXPECT_LT(diff, 204.0 * kMiB) << small->Describe() << " / " << big->Describe();
#endif
}

TEST(CgroupHarness, MissingProgramExits127) {
  VOX_REQUIRE_MEMORY_CGROUP();
  auto r = RunInMemoryCgroup({"/nonexistent/vox_program"}, CgroupRunOptions{});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->exit_code, 127);
  EXPECT_FALSE(r->oom_killed);
}

}  // namespace
}  // namespace vox::testing

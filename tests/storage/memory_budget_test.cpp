// DetectMemoryLimit against fake /proc and /sys trees (cgroup v1, v2, nested,
// none), ParseMemorySize's accepted forms and errors, and the arithmetic of
// SplitMemoryBudget.
#include "core/util/memory_budget.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/common/cgroup_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

class FakeRoot {
 public:
  FakeRoot() {
    root_ = fs::temp_directory_path() /
            ("vox_memory_budget_" + std::to_string(getpid()) + "_" + std::to_string(counter_++));
    fs::remove_all(root_);
    fs::create_directories(root_);
  }
  ~FakeRoot() { fs::remove_all(root_); }
  void Write(const std::string& path, const std::string& text) {
    fs::path p = root_ / path.substr(1);
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
  }
  std::string root() const { return root_.string(); }

 private:
  static inline int counter_ = 0;
  fs::path root_;
};

const char kMemInfo[] =
    "MemTotal:       32000000 kB\n"
    "MemFree:         1000000 kB\n"
    "MemAvailable:    2000000 kB\n"
    "Buffers:           10000 kB\n";
constexpr uint64_t kAvail = uint64_t(2000000) * 1024;

// The mountinfo of a host with cgroup v1 controllers and the v2 hierarchy
// mounted beside them (hybrid), as in a container or a Slurm node.
const char kHybridMountInfo[] =
    "22 1 0:21 / /proc rw,nosuid - proc proc rw\n"
    "31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755\n"
    "32 31 0:29 / /sys/fs/cgroup/cpu rw,relatime shared:9 - cgroup cgroup rw,cpu\n"
    "35 31 0:32 / /sys/fs/cgroup/memory rw,relatime shared:12 - cgroup cgroup rw,memory\n"
    "41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw\n";

TEST(DetectMemoryLimit, NoCgroupUsesMemAvailable) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 0u);
  EXPECT_EQ(m->mem_available, kAvail);
  EXPECT_EQ(m->bytes, kAvail);
  EXPECT_NE(m->ToString().find("MemAvailable"), std::string::npos);
}

TEST(DetectMemoryLimit, NothingFound) {
  FakeRoot r;
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->bytes, 0u);
  EXPECT_EQ(m->ToString(), "no limit found");
}

TEST(DetectMemoryLimit, CgroupV1) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", kHybridMountInfo);
  r.Write("/proc/self/cgroup", "4:memory:/slurm/uid_1/job_7\n2:cpu:/\n0::/\n");
  r.Write("/sys/fs/cgroup/memory/memory.limit_in_bytes", "9223372036854771712\n");
  r.Write("/sys/fs/cgroup/memory/slurm/memory.limit_in_bytes", "9223372036854771712\n");
  r.Write("/sys/fs/cgroup/memory/slurm/uid_1/memory.limit_in_bytes", "9223372036854771712\n");
  r.Write("/sys/fs/cgroup/memory/slurm/uid_1/job_7/memory.limit_in_bytes", "805306368\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 805306368u);
  EXPECT_EQ(m->bytes, 805306368u);
  EXPECT_NE(m->cgroup_file.find("/sys/fs/cgroup/memory/slurm/uid_1/job_7/memory.limit_in_bytes"),
            std::string::npos);
  EXPECT_EQ(m->ToString().rfind("768.0 MiB (cgroup ", 0), 0u) << m->ToString();
}

TEST(DetectMemoryLimit, CgroupV1ParentLimitBindsChild) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", kHybridMountInfo);
  r.Write("/proc/self/cgroup", "4:memory:/job/step/task\n");
  r.Write("/sys/fs/cgroup/memory/job/memory.limit_in_bytes", "536870912\n");
  r.Write("/sys/fs/cgroup/memory/job/step/memory.limit_in_bytes", "9223372036854771712\n");
  r.Write("/sys/fs/cgroup/memory/job/step/task/memory.limit_in_bytes", "1073741824\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 536870912u);
  EXPECT_NE(m->cgroup_file.find("/memory/job/memory.limit_in_bytes"), std::string::npos);
}

TEST(DetectMemoryLimit, CgroupV1CombinedControllersAndUnlimited) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo",
          "35 31 0:32 / /sys/fs/cgroup/cpu,memory rw - cgroup cgroup rw,cpu,memory\n");
  r.Write("/proc/self/cgroup", "3:cpu,memory:/a\n");
  r.Write("/sys/fs/cgroup/cpu,memory/a/memory.limit_in_bytes", "9223372036854771712\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 0u);  // unlimited
  EXPECT_EQ(m->bytes, kAvail);
}

TEST(DetectMemoryLimit, CgroupV2) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", "30 23 0:26 / /sys/fs/cgroup rw,nosuid - cgroup2 cgroup2 rw,nsdelegate\n");
  r.Write("/proc/self/cgroup", "0::/user.slice/job.scope\n");
  r.Write("/sys/fs/cgroup/user.slice/memory.max", "max\n");
  r.Write("/sys/fs/cgroup/user.slice/job.scope/memory.max", "268435456\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 268435456u);
  EXPECT_EQ(m->bytes, 268435456u);
}

TEST(DetectMemoryLimit, CgroupV2MaxEverywhereIsUnlimited) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", "30 23 0:26 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/a/b\n");
  r.Write("/sys/fs/cgroup/a/memory.max", "max\n");
  r.Write("/sys/fs/cgroup/a/b/memory.max", "max\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->cgroup_bytes, 0u);
  EXPECT_EQ(m->bytes, kAvail);
}

TEST(DetectMemoryLimit, CgroupV2ParentAboveChild) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", "30 23 0:26 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/a/b/c\n");
  r.Write("/sys/fs/cgroup/a/memory.max", "104857600\n");
  r.Write("/sys/fs/cgroup/a/b/memory.max", "max\n");
  r.Write("/sys/fs/cgroup/a/b/c/memory.max", "209715200\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->cgroup_bytes, 104857600u);
}

// A container sees a sub-tree of the hierarchy mounted at /sys/fs/cgroup
// (mount root "/kubepods/pod1") while /proc/self/cgroup names the full path.
TEST(DetectMemoryLimit, CgroupV2NestedMountRoot) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo",
          "30 23 0:26 /kubepods/pod1 /sys/fs/cgroup ro,nosuid - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/kubepods/pod1/ctr\n");
  r.Write("/sys/fs/cgroup/memory.max", "314572800\n");  // the pod
  r.Write("/sys/fs/cgroup/ctr/memory.max", "max\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->cgroup_bytes, 314572800u);
}

TEST(DetectMemoryLimit, CgroupOutsideTheMountIsIgnored) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", "30 23 0:26 /other /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/mine\n");
  r.Write("/sys/fs/cgroup/memory.max", "1048576\n");  // /other's limit: not ours
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->cgroup_bytes, 0u);
}

TEST(DetectMemoryLimit, MemAvailableSmallerThanCgroupWins) {
  FakeRoot r;
  r.Write("/proc/meminfo", kMemInfo);
  r.Write("/proc/self/mountinfo", "30 23 0:26 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/big\n");
  r.Write("/sys/fs/cgroup/big/memory.max", "17179869184\n");  // 16 GiB > 2e6 kB
  auto m = DetectMemoryLimit(r.root());
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->cgroup_bytes, 17179869184u);
  EXPECT_EQ(m->bytes, kAvail);
  EXPECT_NE(m->ToString().find("MemAvailable"), std::string::npos);
}

TEST(DetectMemoryLimit, GarbageLimitFileIsAnErrorNamingIt) {
  FakeRoot r;
  r.Write("/proc/self/mountinfo", "30 23 0:26 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n");
  r.Write("/proc/self/cgroup", "0::/x\n");
  r.Write("/sys/fs/cgroup/x/memory.max", "lots\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().ToString().find("/sys/fs/cgroup/x/memory.max"), std::string::npos);
  EXPECT_NE(m.status().ToString().find("lots"), std::string::npos);
}

TEST(DetectMemoryLimit, GarbageMemInfoIsAnError) {
  FakeRoot r;
  r.Write("/proc/meminfo", "MemAvailable: many\n");
  auto m = DetectMemoryLimit(r.root());
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().ToString().find("meminfo"), std::string::npos);
}

// The real machine: whatever it finds must be consistent.
TEST(DetectMemoryLimit, ThisProcess) {
  auto m = DetectMemoryLimit();
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_GT(m->mem_available, 0u);
  EXPECT_GT(m->bytes, 0u);
  EXPECT_LE(m->bytes, m->mem_available);
  if (m->cgroup_bytes != 0) {
    EXPECT_LE(m->bytes, m->cgroup_bytes);
  }
}

// Run by RealCgroupLimitIsDetected in a child process inside a cgroup:
// prints what this process detects. Disabled, so a normal run neither runs
// nor counts it as skipped; the parent asks for it by name.
TEST(DetectMemoryLimit, DISABLED_ChildReportsLimit) {
  auto m = DetectMemoryLimit();
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  printf("cgroup_bytes=%llu bytes=%llu\n", (unsigned long long)m->cgroup_bytes, (unsigned long long)m->bytes);
}

// The real kernel: this test program, re-run in a fresh 96 MiB cgroup,
// finds 96 MiB (a fake tree cannot show that the paths are the kernel's).
TEST(DetectMemoryLimit, RealCgroupLimitIsDetected) {
  VOX_REQUIRE_MEMORY_CGROUP();
  char self[4096] = {0};
  ASSERT_GT(::readlink("/proc/self/exe", self, sizeof self - 1), 0);
  testing::CgroupRunOptions o;
  o.limit_bytes = 96 * kMiB;
  o.stdout_path = ::testing::TempDir() + "memory_budget_child_" + std::to_string(getpid()) + ".txt";
  auto r = testing::RunInMemoryCgroup({self, "--gtest_also_run_disabled_tests",
                                   "--gtest_filter=DetectMemoryLimit.DISABLED_ChildReportsLimit"}, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->exit_code, 0) << r->Describe();
  std::ifstream in(o.stdout_path);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  fs::remove(o.stdout_path);
  const std::string want = "cgroup_bytes=" + std::to_string(96 * kMiB) + " bytes=" + std::to_string(96 * kMiB);
  EXPECT_NE(text.find(want), std::string::npos) << text;
}

TEST(ParseMemorySize, Forms) {
  struct Case {
    const char* text;
    uint64_t bytes;
  } cases[] = {
      {"512", 512 * kMiB},     {"512M", 512 * kMiB},        {"512m", 512 * kMiB},
      {"512MiB", 512 * kMiB},  {"512MB", 512 * kMiB},       {"2G", 2048 * kMiB},
      {"2g", 2048 * kMiB},     {"1.5G", 1536 * kMiB},       {"65536K", 64 * kMiB},
      {"1T", uint64_t(1) << 40}, {"1", kMiB},               {"0.5GiB", 512 * kMiB},
  };
  for (const Case& c : cases) {
    auto v = ParseMemorySize("--memory-mb", c.text);
    ASSERT_TRUE(v.ok()) << c.text << ": " << v.status().ToString();
    EXPECT_EQ(*v, c.bytes) << c.text;
  }
}

TEST(ParseMemorySize, Errors) {
  struct Case {
    const char* text;
    const char* why;
  } cases[] = {
      {"", "expected a size"},
      {"0", "must be positive"},
      {"0G", "must be positive"},
      {"-5", "must be positive"},
      {"abc", "not a number"},
      {"1.2.3G", "not a number"},
      {"12X", "unknown unit"},
      {"12MM", "unknown unit"},
      {"512K", "below 1 MiB"},
      {"99999999999999999999", "too large"},
      {"9999999999T", "too large"},
      {"4194304T", "too large"},  // 2^62 bytes exactly is still fine; this is 2^62
  };
  for (const Case& c : cases) {
    auto v = ParseMemorySize("--memory-mb", c.text);
    if (std::string(c.text) == "4194304T") {
      // 2^22 TiB = 2^62 bytes: the largest accepted size.
      ASSERT_TRUE(v.ok()) << v.status().ToString();
      EXPECT_EQ(*v, uint64_t(1) << 62);
      continue;
    }
    ASSERT_FALSE(v.ok()) << c.text << " parsed as " << *v;
    const std::string msg = v.status().ToString();
    EXPECT_NE(msg.find("--memory-mb"), std::string::npos) << msg;
    EXPECT_NE(msg.find(std::string("'") + c.text + "'"), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.why), std::string::npos) << c.text << ": " << msg;
  }
  auto over = ParseMemorySize("--memory-mb", "4194305T");
  EXPECT_FALSE(over.ok());
}

BudgetInputs TypicalInputs() {
  BudgetInputs in;
  in.resident_bytes = 3 * kMiB;
  in.max_brick_bytes = 64 * 1024;
  in.max_stored_brick_bytes = 16 * 1024;
  in.image_width = 1024;
  in.image_height = 1024;
  in.tile_size = 64;
  in.threads = 2;
  in.channels = 5;
  return in;
}

uint64_t Sum(const MemoryBudget& b) {
  return b.process_base + b.headroom + b.resident_top + b.tile_buffers + b.exr_writer + b.page_cache +
         b.brick_pins + b.brick_cache + b.unused;
}

TEST(SplitMemoryBudget, Arithmetic) {
  const BudgetInputs in = TypicalInputs();
  const uint64_t total = 768 * kMiB;
  auto b = SplitMemoryBudget(total, in);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->total, total);
  EXPECT_EQ(Sum(*b), total);
  EXPECT_EQ(b->process_base, BudgetInputs::kDefaultProcessBase);
  EXPECT_EQ(b->headroom, 96 * kMiB);
  EXPECT_EQ(b->resident_top, 3 * kMiB);
  EXPECT_EQ(b->tile_buffers, 2u * 64 * 64 * 5 * 4);                    // 160 KiB
  EXPECT_EQ(b->exr_writer, 2u * 2 * 64 * 64 * 5 * 4 + 256 * 8 + 1024u * 64 * 16);
  // 2 threads x (16 KiB record + 256 KiB read-ahead + a 1 MiB record window twice).
  EXPECT_EQ(b->page_cache, 2 * (16 * 1024 + 256 * 1024 + 2 * kMiB));
  // 256 pins x 64 KiB x 2 threads = 32 MiB < (768 - fixed) / 8: all wanted pins.
  EXPECT_EQ(b->pins_per_thread, 256);
  EXPECT_EQ(b->brick_pins, 32 * kMiB);
  EXPECT_EQ(b->unused, 0u);
  const uint64_t fixed = b->process_base + b->headroom + b->resident_top + b->tile_buffers +
                         b->exr_writer + b->page_cache;
  EXPECT_EQ(b->brick_cache, total - fixed - 32 * kMiB);
  EXPECT_NE(b->ToString().find("budget 768.0 MiB"), std::string::npos) << b->ToString();
  EXPECT_NE(b->ToJson().find("\"brick_cache\": " + std::to_string(b->brick_cache)), std::string::npos);
}

TEST(SplitMemoryBudget, PinsShrinkToAnEighthOfWhatIsLeft) {
  BudgetInputs in = TypicalInputs();
  const uint64_t total = 96 * kMiB;
  auto b = SplitMemoryBudget(total, in);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  const uint64_t left = total - (b->process_base + b->headroom + b->resident_top + b->tile_buffers +
                                 b->exr_writer + b->page_cache);
  EXPECT_LE(b->brick_pins, left / 8);
  EXPECT_GT(2 * b->brick_pins, left / 8);  // the largest power of two that fits
  EXPECT_EQ(b->brick_pins, uint64_t(in.threads) * b->pins_per_thread * in.max_brick_bytes);
  EXPECT_EQ(b->brick_cache, left - b->brick_pins);
  EXPECT_EQ(Sum(*b), total);
}

TEST(SplitMemoryBudget, TooSmallSaysWhatItNeeds) {
  BudgetInputs in = TypicalInputs();
  in.resident_bytes = 100 * kMiB;  // a big top
  auto b = SplitMemoryBudget(64 * kMiB, in);
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), StatusCode::kResourceExhausted);
  const std::string msg = b.status().ToString();
  EXPECT_NE(msg.find("64.0 MiB is too small"), std::string::npos) << msg;
  EXPECT_NE(msg.find("resident top 100.0,"), std::string::npos) << msg;
  // The figure it names is enough, and a MiB less is not.
  const size_t at = msg.find("needs at least ");
  ASSERT_NE(at, std::string::npos) << msg;
  const double need_mib = std::stod(msg.substr(at + 15));
  const uint64_t need = uint64_t(std::ceil(need_mib * double(kMiB))) + kMiB / 10;
  EXPECT_TRUE(SplitMemoryBudget(need, in).ok()) << need_mib;
  EXPECT_FALSE(SplitMemoryBudget(need - kMiB, in).ok()) << need_mib;
}

TEST(SplitMemoryBudget, ACacheFloorRaisesTheNeedAndTheFlagItNamesSuffices) {
  BudgetInputs in = TypicalInputs();
  in.min_cache_bytes = 40 * kMiB;  // e.g. a store and its pyramid's 9 levels, 4 MiB each
  EXPECT_EQ(MinBrickCacheBytes(in), 40 * kMiB);
  auto b = SplitMemoryBudget(64 * kMiB, in);
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), StatusCode::kResourceExhausted);
  const std::string msg = b.status().ToString();
  EXPECT_NE(msg.find("brick cache 40.0,"), std::string::npos) << msg;
  const size_t at = msg.find("--memory-mb ");
  ASSERT_NE(at, std::string::npos) << msg;
  const uint64_t flag = std::stoull(msg.substr(at + 12));
  auto ok = SplitMemoryBudget(flag * kMiB, in);
  ASSERT_TRUE(ok.ok()) << msg << "\n" << ok.status().ToString();
  EXPECT_GE(ok->brick_cache, 40 * kMiB);
  EXPECT_EQ(Sum(*ok), flag * kMiB);
  EXPECT_FALSE(SplitMemoryBudget((flag - 1) * kMiB, in).ok()) << msg;
}

TEST(SplitMemoryBudget, CacheFloor) {
  BudgetInputs in = TypicalInputs();
  in.threads = 64;
  in.max_brick_bytes = 1 * kMiB;  // 64 threads x 4 bricks = 256 MiB minimum cache
  EXPECT_EQ(MinBrickCacheBytes(in), 256 * kMiB);
  auto small = SplitMemoryBudget(300 * kMiB, in);
  ASSERT_FALSE(small.ok());
  auto big = SplitMemoryBudget(2048 * kMiB, in);
  ASSERT_TRUE(big.ok()) << big.status().ToString();
  EXPECT_GE(big->brick_cache, 256 * kMiB);
  EXPECT_GE(big->pins_per_thread, 1);
  EXPECT_EQ(Sum(*big), 2048 * kMiB);
}

TEST(SplitMemoryBudget, CacheOverrideInsideTheBudget) {
  BudgetInputs in = TypicalInputs();
  in.cache_override = 100 * kMiB;
  auto b = SplitMemoryBudget(768 * kMiB, in);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->brick_cache, 100 * kMiB);
  EXPECT_GT(b->unused, 0u);
  EXPECT_EQ(Sum(*b), 768 * kMiB);
  EXPECT_NE(b->ToString().find("unused"), std::string::npos);

  in.cache_override = 1024 * kMiB;  // a 1 GiB cache does not fit in 768 MiB
  auto over = SplitMemoryBudget(768 * kMiB, in);
  ASSERT_FALSE(over.ok());
  EXPECT_EQ(over.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(over.status().ToString().find("1024.0 MiB does not fit"), std::string::npos)
      << over.status().ToString();

  in.cache_override = 1 * kMiB;  // below the floor
  EXPECT_FALSE(SplitMemoryBudget(768 * kMiB, in).ok());
}

TEST(SplitMemoryBudget, BadInputs) {
  BudgetInputs in = TypicalInputs();
  in.threads = 0;
  EXPECT_EQ(SplitMemoryBudget(768 * kMiB, in).status().code(), StatusCode::kInvalidArgument);
  in = TypicalInputs();
  in.pins_per_thread = 512;
  EXPECT_FALSE(SplitMemoryBudget(768 * kMiB, in).ok());
  in = TypicalInputs();
  in.image_width = 0;
  EXPECT_FALSE(SplitMemoryBudget(768 * kMiB, in).ok());
}

}  // namespace
}  // namespace vox

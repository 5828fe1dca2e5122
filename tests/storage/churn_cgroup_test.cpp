// The brick cache's churn under a job's memory limit: exact frames of a
// vox-gen sphere with small bricks (1024^3, 8^3-voxel bricks: tens of
// thousands of bricks of many sizes per frame) rendered in a 64 MiB memory
// cgroup with a small brick cache, frame after frame, about a million
// evictions in all. The process's peak resident set stays inside the budget
// the cgroup gives it, the cgroup never hits its limit (failcnt 0: the
// store, 23 MB, fits beside the process, so even its page cache is never
// reclaimed) and nothing is killed; the bricks live in the brick pool
// (storage/buffer_pool.h), which never overflows to the heap, and the heap
// keeps next to nothing beyond its live blocks. Needs a writable memory
// cgroup (root; CI runs as root and does not skip it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/common/cgroup_util.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;
constexpr int kFrames = 36;

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(BrickChurnInCgroup, AMillionEvictionsStayInsideTheBudget) {
  VOX_REQUIRE_MEMORY_CGROUP();
  char tmpl[] = "/tmp/vox_churn_XXXXXX";
  ASSERT_NE(mkdtemp(tmpl), nullptr);
  const fs::path dir = tmpl;
  struct Cleanup {
    fs::path d;
    ~Cleanup() { fs::remove_all(d); }
  } cleanup{dir};
  const std::string store = (dir / "sphere").string();
  const std::string gen = std::string(VOX_GEN_BIN) + " sphere " + store +
                          " --size 1024 --levels 7+3 --no-lod --quiet";
  ASSERT_EQ(std::system(gen.c_str()), 0) << gen;

  CgroupRunOptions o;
  o.limit_bytes = 64 * kMiB;
  o.stderr_path = (dir / "stderr.txt").string();
  const std::vector<std::string> argv = {
      VOX_RENDER_BIN, store, "-o", (dir / "f.%02d.exr").string(), "--stats", (dir / "f.%02d.json").string(),
      "--lod", "0", "--threads", "2", "--size", "512x512", "--turntable", std::to_string(kFrames),
      "--cache-mb", "4", "--quiet"};
  auto r = RunInMemoryCgroup(argv, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::string log = ReadAll(o.stderr_path);
  ASSERT_EQ(r->exit_code, 0) << r->Describe() << "\n" << log;
  EXPECT_FALSE(r->oom_killed) << r->Describe();
  EXPECT_EQ(r->failcnt, 0u) << r->Describe();
  EXPECT_LE(r->peak_bytes, o.limit_bytes) << r->Describe();

  uint64_t evictions = 0, misses = 0;
  for (int f = 1; f <= kFrames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "f.%02d.json", f);
    const auto j = nlohmann::json::parse(ReadAll((dir / name).string()));
    const auto& m = j["memory"];
    const auto& pool = m["brick_pool"];
    const auto& p = m["process"];
    SCOPED_TRACE("frame " + std::to_string(f) + ": " + m.dump());
    evictions += j["cache"]["evictions"].get<uint64_t>();
    misses += j["cache"]["misses"].get<uint64_t>();
    // The budget is the cgroup's; the process's peak stays inside it.
    EXPECT_EQ(m["total"].get<uint64_t>(), o.limit_bytes);
    EXPECT_LE(p["peak_rss"].get<uint64_t>(), m["total"].get<uint64_t>());
    // The bricks live in the pool, which is what the budget gave the cache and pins.
    EXPECT_GT(pool["peak_in_use"].get<uint64_t>(), 0u);
    EXPECT_LE(pool["peak_in_use"].get<uint64_t>(), pool["capacity"].get<uint64_t>());
    EXPECT_LE(pool["capacity"].get<uint64_t>(),
              m["brick_cache"].get<uint64_t>() + m["brick_pins"].get<uint64_t>());
    EXPECT_EQ(pool["overflows"].get<uint64_t>(), 0u);
    // The heap holds next to nothing beyond its live blocks, whatever the churn.
    EXPECT_LE(p["heap_held"].get<uint64_t>() - p["heap_in_use"].get<uint64_t>(), 2 * kMiB);
  }
  std::printf("%d frames: %llu misses, %llu evictions, peak charge %llu MiB of %llu\n", kFrames,
              (unsigned long long)misses, (unsigned long long)evictions,
              (unsigned long long)(r->peak_bytes / kMiB), (unsigned long long)(o.limit_bytes / kMiB));
  EXPECT_GE(evictions, 900000u);
}

}  // namespace
}  // namespace vox::testing

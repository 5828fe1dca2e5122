// The memory budget as a promise, in real memory cgroups (v1 or v2): a render
// whose image and options cannot fit the cgroup's limit stops at the start,
// before any output, naming the smallest budget it needs; given exactly that
// (as the cgroup's limit, the budget detected from it), the same render
// finishes, is not killed, and its peak resident set stays inside the budget.
// And a cheap corner of the 256 MiB matrix: the exact frame with shadows and
// reflections at 16 threads renders in 256 MiB. The store is a vox-gen
// sphere with its pyramid, the image 8192x8192 from a camera far enough away
// that the sphere covers a few hundred thousand of its pixels (so the frame
// is quick, while every per-image and per-thread cost is that of 8192^2).
// Needs a writable memory cgroup (root; CI runs as root and does not skip it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "tests/common/cgroup_util.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;

void WriteAll(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

class BudgetCgroupTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!MemoryCgroupUnavailable().empty()) return;
    std::string tmpl = (fs::temp_directory_path() / "vox_budget_cgroup_XXXXXX").string();
    ASSERT_NE(mkdtemp(tmpl.data()), nullptr);
    dir_ = new std::string(tmpl);
    const std::string gen =
        std::string(VOX_GEN_BIN) + " sphere " + Store() + " --size 2048 --quiet";
    ASSERT_EQ(std::system(gen.c_str()), 0) << gen;
    // The unit sphere from 20 units away: about 430,000 of the 8192^2 pixels.
    WriteAll(*dir_ + "/far.json",
             R"({"position": [0, 0, 20], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 40,)"
             R"( "width": 8192, "height": 8192})");
    WriteAll(*dir_ + "/scene.json",
             R"({"lights": [{"type": "directional", "direction": [-1, -1, -1], "shadows": true}],)"
             R"( "material": {"reflect": 0.3}})");
  }
  static void TearDownTestSuite() {
    if (dir_ != nullptr) fs::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Store() { return *dir_ + "/sphere"; }
  static std::string Path(const std::string& name) { return *dir_ + "/" + name; }

  struct Run {
    CgroupRunResult result;
    std::string log;
    double seconds = 0;
  };
  static Run Render(const std::string& name, uint64_t limit_bytes,
                    const std::vector<std::string>& flags) {
    CgroupRunOptions o;
    o.limit_bytes = limit_bytes;
    o.drop_page_cache = true;
    o.stderr_path = Path(name + ".log");
    std::vector<std::string> argv = {
        VOX_RENDER_BIN,       Store(),  "-o", Path(name + ".exr"), "--stats",
        Path(name + ".json"), "--quiet"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    const auto t0 = std::chrono::steady_clock::now();
    auto r = RunInMemoryCgroup(argv, o);
    Run run;
    run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (r.ok()) run.result = *r;
    run.log = ReadAll(o.stderr_path);
    return run;
  }

  // Refused in 64 MiB at the start, then rendered in the budget the refusal named.
  void RefusesThenRendersAtTheStatedNeed(const std::string& name,
                                         const std::vector<std::string>& flags) {
    const uint64_t tight = 64 * kMiB;
    Run refused = Render(name + "_64", tight, flags);
    SCOPED_TRACE(refused.log);
    EXPECT_FALSE(refused.result.oom_killed) << refused.result.Describe();
    ASSERT_EQ(refused.result.exit_code, 1) << refused.result.Describe();
    EXPECT_FALSE(fs::exists(Path(name + "_64.exr")));
    EXPECT_FALSE(fs::exists(Path(name + "_64.json")));
    std::smatch m;
    ASSERT_TRUE(std::regex_search(refused.log, m, std::regex("needs at least ([0-9.]+) MiB")));
    EXPECT_NE(refused.log.find("--memory-mb"), std::string::npos);
    const double need = std::stod(m[1].str());
    EXPECT_GT(need, 64.0);
    // At the start: before any brick is read (the store's index and top only).
    EXPECT_LT(refused.result.peak_bytes, 48 * kMiB) << refused.result.Describe();

    const uint64_t limit = uint64_t(std::ceil(need)) * kMiB;
    Run ok = Render(name + "_need", limit, flags);
    std::printf("%s: 64 MiB refused in %.1f s, needs %.1f MiB; in %llu MiB: %s, %.1f s\n",
                name.c_str(), refused.seconds, need, (unsigned long long)(limit / kMiB),
                ok.result.Describe().c_str(), ok.seconds);
    EXPECT_FALSE(ok.result.oom_killed) << ok.result.Describe() << "\n" << ok.log;
    ASSERT_EQ(ok.result.exit_code, 0) << ok.result.Describe() << "\n" << ok.log;
    EXPECT_LE(ok.result.peak_bytes, limit);
    const auto j = nlohmann::json::parse(ReadAll(Path(name + "_need.json")));
    const auto& mem = j["memory"];
    SCOPED_TRACE(mem.dump());
    EXPECT_EQ(mem["total"].get<uint64_t>(), limit);  // the budget is the cgroup's limit
    EXPECT_LE(mem["process"]["peak_rss"].get<uint64_t>(), limit);
    EXPECT_EQ(mem["brick_pool"]["overflows"].get<uint64_t>(), 0u);
    EXPECT_GT(j["cache"]["misses"].get<uint64_t>(), 0u);  // it read bricks
  }

  static std::string* dir_;
};

std::string* BudgetCgroupTest::dir_ = nullptr;

TEST_F(BudgetCgroupTest, LargeImageRefusesAtStartAndRendersInTheBudgetItNames) {
  VOX_REQUIRE_MEMORY_CGROUP();
  // The default level of detail opens the pyramid: each level's minimal cache counts.
  RefusesThenRendersAtTheStatedNeed(
      "default_t2", {"--cam", Path("far.json"), "--scene", Path("scene.json"), "--threads", "2"});
}

TEST_F(BudgetCgroupTest, LargeExactImageRefusesAtStartAndRendersInTheBudgetItNames) {
  VOX_REQUIRE_MEMORY_CGROUP();
  // 16 threads: each thread's tiles, pins and reads in flight count.
  RefusesThenRendersAtTheStatedNeed(
      "exact_t16",
      {"--cam", Path("far.json"), "--scene", Path("scene.json"), "--lod", "0", "--threads", "16"});
}

// The cheap corner of the 256 MiB matrix (tools/bench/vbench.py budget runs all of it): the
// full view at 1024^2 with shadows and reflections, exact and default, at 16 threads (the most
// per-thread memory), cold, in 256 MiB.
TEST_F(BudgetCgroupTest, FramesWithShadowsAndReflectionsAt16ThreadsRenderIn256MiB) {
  VOX_REQUIRE_MEMORY_CGROUP();
  WriteAll(Path("full.json"), R"({"position": [0, 0, 3], "look_at": [0, 0, 0], "up": [0, 1, 0],)"
                              R"( "fov_deg": 40, "width": 1024, "height": 1024})");
  const uint64_t limit = 256 * kMiB;
  for (const bool exact : {true, false}) {
    const std::string name = exact ? "m_exact" : "m_default";
    std::vector<std::string> flags = {
        "--cam", Path("full.json"), "--scene", Path("scene.json"), "--threads", "16"};
    if (exact) flags.insert(flags.end(), {"--lod", "0"});
    Run r = Render(name, limit, flags);
    std::printf("%s in 256 MiB: %s, %.1f s\n", name.c_str(), r.result.Describe().c_str(),
                r.seconds);
    EXPECT_FALSE(r.result.oom_killed) << r.result.Describe();
    ASSERT_EQ(r.result.exit_code, 0) << r.result.Describe() << "\n" << r.log;
    const auto j = nlohmann::json::parse(ReadAll(Path(name + ".json")));
    const auto& mem = j["memory"];
    SCOPED_TRACE(mem.dump());
    EXPECT_EQ(mem["total"].get<uint64_t>(), limit);
    EXPECT_LE(mem["process"]["peak_rss"].get<uint64_t>(), limit);
    EXPECT_EQ(mem["brick_pool"]["overflows"].get<uint64_t>(), 0u);
    EXPECT_GT(j["cache"]["misses"].get<uint64_t>(), 1000u);
  }
}

}  // namespace
}  // namespace vox::testing

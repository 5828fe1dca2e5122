// vox-render's memory budget: --memory-mb parsing and its errors (no output
// left behind), a budget below what the store needs (the error names the
// MiB, and that many MiB is enough), the brick cache and the per-thread
// pinned-brick tables staying within their shares of a tiny budget while
// the image stays the one an unlimited render makes, and a brick file
// truncated under a running render.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>

#include "render/exr.h"
#include "render/frame.h"
#include "render/job.h"
#include "render/renderer.h"
#include "storage/brick_table.h"
#include "storage/store.h"
#include "storage/store_budget.h"
#include "tests/common/run_command.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

using RunResult = testing::CommandResult;

class MemoryBudgetRenderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_budget_render_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    // A 256^3 shell (radius 100..110 voxels, some 2.9M voxels in 16^3
    // bricks, with normals and colours): the bricks a view touches decode to
  // more than the smallest budget's cache.
    StoreMeta meta = testing::TestMeta(8, GridClass::kLevelSet, 0.04);
    meta.brick_level = 4;
    meta.origin = {-128, -128, -128};
    meta.index_to_world = glm::scale(glm::dmat4(1.0), glm::dvec3(0.04));
    meta.source_file = "generated";
    meta.grid_name = "shell";
    meta.has_color = true;  // three more bytes per voxel once decoded
    Status s = testing::WriteStore(Path("store"), meta,
                                   testing::ShellVoxels(256, glm::dvec3(128), 100, 110));
    ASSERT_TRUE(s.ok()) << s.ToString();
    std::ofstream(Path("cam.json"))
        << R"({"position":[0,1,12], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40,)"
           R"( "width":192, "height":160, "projection":"perspective"})";
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string Render(const std::string& args) {
    return std::string(VOX_RENDER_BIN) + " " + Path("store") + " --cam " + Path("cam.json") +
           " --threads 2 " + args;
  }
  static fs::path* dir_;
};
fs::path* MemoryBudgetRenderTest::dir_ = nullptr;

void ExpectSamePixels(const std::string& a_path, const std::string& b_path) {
  auto a = ReadExr(a_path);
  auto b = ReadExr(b_path);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  ASSERT_EQ(a->pixels.size(), b->pixels.size());
  size_t hits = 0;
  for (float alpha : a->pixels.at("A")) hits += alpha > 0;
  EXPECT_GT(hits, a->pixels.at("A").size() / 10);  // the shell is in view
  for (const auto& [name, pa] : a->pixels) {
    const std::vector<float>& pb = b->pixels.at(name);
    ASSERT_EQ(pa.size(), pb.size());
    EXPECT_EQ(std::memcmp(pa.data(), pb.data(), pa.size() * sizeof(float)), 0) << name;
  }
}

TEST_F(MemoryBudgetRenderTest, BadMemoryFlagsFailWithoutOutput) {
  for (const char* bad : {"0", "abc", "-5", "12X", ""}) {
    SCOPED_TRACE(bad);
    const std::string out = Path("bad.exr");
    RunResult r = testing::RunCommand(Render(std::string("--quiet --memory-mb '") + bad + "' -o " + out));
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("--memory-mb"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out));
  }
}

TEST_F(MemoryBudgetRenderTest, BudgetBelowTheStoreNeedsNamesTheMiBAndThatSuffices) {
  const std::string out = Path("small.exr");
  RunResult r = testing::RunCommand(Render("--quiet --memory-mb 8 -o " + out + " --stats " + Path("small.json")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("store"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("resident top"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(Path("small.json")));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, std::regex("needs at least ([0-9.]+) MiB"))) << r.output;
  const double need = std::stod(m[1].str());
  EXPECT_GT(need, 8.0);
  // The stated need is enough (rounded up to whole MiB).
  const int enough = int(std::ceil(need));
  RunResult ok = testing::RunCommand(Render("--quiet --memory-mb " + std::to_string(enough) + " -o " + out));
  EXPECT_EQ(ok.code, 0) << ok.output;
  // One MiB less is not.
  RunResult less = testing::RunCommand(Render("--quiet --memory-mb " + std::to_string(enough - 1) + " -o " +
                               Path("less.exr")));
  EXPECT_EQ(less.code, 1) << less.output;
  EXPECT_FALSE(fs::exists(Path("less.exr")));
}

TEST_F(MemoryBudgetRenderTest, CacheAndTablesStayWithinTheirSharesOfATinyBudget) {
  // Unlimited reference (an explicit budget far above the store).
  RenderJobOptions big;
  big.store_dir = Path("store");
  big.camera_path = Path("cam.json");
  big.exr_path = Path("big.exr");
  big.stats_path = Path("big.json");
  big.threads = 2;
  big.quiet = true;
  big.memory_bytes = uint64_t(4) << 30;
  ASSERT_TRUE(RunRenderJob(big).ok());

  // The smallest budget the render takes: what a too small one says it needs.
  RenderJobOptions tiny = big;
  tiny.exr_path = Path("tiny.exr");
  tiny.stats_path = Path("tiny.json");
  tiny.memory_bytes = uint64_t(8) << 20;
  Status s = RunRenderJob(tiny);
  ASSERT_EQ(s.code(), StatusCode::kResourceExhausted) << s.ToString();
  std::smatch m;
  const std::string msg = s.ToString();
  ASSERT_TRUE(std::regex_search(msg, m, std::regex("needs at least ([0-9.]+) MiB"))) << msg;
  const uint64_t need_mib = uint64_t(std::ceil(std::stod(m[1].str())));
  EXPECT_FALSE(fs::exists(tiny.exr_path));
  tiny.memory_bytes = need_mib << 20;
  s = RunRenderJob(tiny);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ExpectSamePixels(big.exr_path, tiny.exr_path);

  nlohmann::json j;
  std::ifstream(tiny.stats_path) >> j;
  const nlohmann::json& mem = j["memory"];
  const uint64_t total = mem["total"];
  EXPECT_EQ(total, need_mib << 20);
  uint64_t parts = 0;
  for (const char* k : {"process_base", "headroom", "resident_top", "tile_buffers", "exr_writer",
                        "page_cache", "brick_pins", "brick_cache", "unused"})
    parts += mem[k].get<uint64_t>();
  EXPECT_EQ(parts, total);
  // The cache ran at its share, less what it gave up to the heap's growth
  // past the budget (HeapWatch: this test process holds more than the tiny
  // budget plans for), and had to evict (the decoded store is larger),
  // never holding more than it.
  const uint64_t cache = mem["brick_cache"];
  EXPECT_EQ(j["cache"]["capacity"].get<uint64_t>() + j["cache"]["given_to_heap"].get<uint64_t>(),
            cache);
  EXPECT_LE(j["cache"]["bytes_resident"].get<uint64_t>(), cache);
  EXPECT_GT(j["cache"]["evictions"].get<uint64_t>(), 0u);
  // The tables: slots x the largest brick within the pins' share per thread.
  const uint64_t slots = mem["table_slots"], max_brick = mem["max_brick_bytes"];
  EXPECT_EQ(slots, mem["pins_per_thread"].get<uint64_t>());
  EXPECT_LE(2 * slots * max_brick, mem["brick_pins"].get<uint64_t>());
  nlohmann::json jb;
  std::ifstream(big.stats_path) >> jb;
  EXPECT_GT(jb["memory"]["table_slots"].get<uint64_t>(), slots);
  EXPECT_EQ(jb["cache"]["evictions"].get<uint64_t>(), 0u);

  // A table of that size pins at most its slots, whatever it is asked for.
  auto store = Store::Open(Path("store"), OpenOptions());
  ASSERT_TRUE(store.ok());
  const int bits = LendingBrickTable::SlotBitsForBytes(mem["brick_pins"].get<uint64_t>() / 2,
                                                       (*store)->brick_sizes().max_decoded);
  EXPECT_EQ(uint64_t(1) << bits, slots);
  LendingBrickTable table(store->get(), bits);
  for (uint32_t id = 0; id < (*store)->meta().brick_count; ++id) {
    Status e;
    ASSERT_NE(table.LendBrick(id, &e), nullptr) << e.ToString();
    ASSERT_LE(table.pinned(), table.num_slots());
  }
  EXPECT_EQ(table.num_slots(), slots);
}

TEST(SlotBitsForBytes, LargestPowerOfTwoWithinTheBytes) {
  EXPECT_EQ(LendingBrickTable::SlotBitsForBytes(1000, 100), 3);  // 8 x 100 <= 1000 < 16 x 100
  EXPECT_EQ(LendingBrickTable::SlotBitsForBytes(99, 100), 0);    // one slot, however small
  EXPECT_EQ(LendingBrickTable::SlotBitsForBytes(uint64_t(1) << 40, 100), 8);  // at most 256
  EXPECT_EQ(LendingBrickTable::SlotBitsForBytes(200, 100), 1);
}

TEST_F(MemoryBudgetRenderTest, BrickFileTruncatedDuringTheRenderIsAnError) {
  const std::string copy = Path("trunc.store");
  fs::copy(Path("store"), copy);
  OpenOptions oo;
  oo.cache_bytes = 1 << 20;
  auto store = Store::Open(copy, oo);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  auto camera = LoadCamera(Path("cam.json"));
  ASSERT_TRUE(camera.ok());
  auto renderer = Renderer::Create(store->get(), *camera, Scene(), RenderOptions());
  ASSERT_TRUE(renderer.ok());
  // The bricks go after open: as when a job's scratch file is cut short.
  fs::resize_file(copy + "/bricks.vxb", fs::file_size(copy + "/bricks.vxb") / 3);
  FrameOptions fo;
  fo.exr_path = Path("trunc.exr");
  fo.threads = 2;
  FrameStats stats;
  Status s = RenderFrame(**renderer, fo, &stats);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.ToString().find("bricks.vxb"), std::string::npos) << s.ToString();
  EXPECT_NE(s.ToString().find("shrank"), std::string::npos) << s.ToString();
}

}  // namespace
}  // namespace vox

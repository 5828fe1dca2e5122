// Fog under the memory budget, in a real memory cgroup (v1 or v2): a fog
// volume whose decoded bricks are several times the brick cache renders,
// cold, with shadows, exactly and with the default level of detail, inside a
// tight limit. Fog bricks cost more than their cells and densities: decoding
// finds their blocks of one density and keeps, per voxel, the size of its
// block (up to half a byte a voxel, DecodedBrick::uniform_levels), and the
// cache must charge it. The volume is a terraced ball, an integer field as a
// scanner writes it (16 densities in shells), so that most bricks hold blocks
// of one density without being of one density whole; it goes in through
// vox-ingest's raw array input. The checks: the process is neither killed
// nor refused, the cgroup never hits its limit (failcnt 0: the store, 5 MB
// on disk, fits beside the process), the peak resident set stays inside the
// budget, the brick pool never has to evict to make room nor overflow to the
// heap (it would if the cache charged less than the bricks hold), what the
// pool holds at the end is no more than what the base store's cache charged
// for, the cache evicted, and the image is the one rendered without a limit.
// Needs a writable memory cgroup (root; CI runs as root and does not skip it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "render/exr.h"
#include "tests/common/cgroup_util.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;
constexpr int kGrid = 384;         // voxels per axis of the array
constexpr double kRadius = 180.0;  // the ball's radius in voxels
constexpr int kTerraces = 16;      // densities 1..16, the densest at the centre
constexpr uint64_t kLimit = 80 * kMiB;

class FogBudgetCgroupTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!MemoryCgroupUnavailable().empty()) return;
    std::string tmpl = (fs::temp_directory_path() / "vox_fog_budget_XXXXXX").string();
    ASSERT_NE(mkdtemp(tmpl.data()), nullptr);
    dir_ = new std::string(tmpl);
    // The terraced ball: ceil(16 (1 - r^2 / R^2)) where positive, as uint8.
    const std::string raw = Path("terraced.raw");
    {
      std::ofstream out(raw, std::ios::binary);
      std::vector<char> row(kGrid);
      const double c = (kGrid - 1) / 2.0;
      for (int i = 0; i < kGrid; ++i)
        for (int j = 0; j < kGrid; ++j) {
          for (int k = 0; k < kGrid; ++k) {
            const double x = i - c, y = j - c, z = k - c;
            const double d = 1.0 - (x * x + y * y + z * z) / (kRadius * kRadius);
            row[k] = char(d > 0 ? int(std::ceil(d * kTerraces)) : 0);
          }
          out.write(row.data(), kGrid);
        }
      ASSERT_TRUE(out.good());
    }
    const std::string n = std::to_string(kGrid);
    const std::string ingest = std::string(VOX_INGEST_BIN) + " " + raw + " " + Store() +
                               " --shape " + n + "," + n + "," + n +
                               " --dtype uint8 --voxel-size 0.005 --threshold 0 --quiet";
    ASSERT_EQ(std::system(ingest.c_str()), 0) << ingest;
    fs::remove(raw);
    std::ofstream(Path("scene.json"))
        << R"({"lights": [{"type": "directional", "direction": [-1, -1, -1], "shadows": true}],)"
           R"( "volume": {"absorption": 0.1, "scattering": 0.1}})";
  }
  static void TearDownTestSuite() {
    if (dir_ != nullptr) fs::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Store() { return *dir_ + "/terraced"; }
  static std::string Path(const std::string& name) { return *dir_ + "/" + name; }

  static std::vector<std::string> RenderArgs(const std::string& name, bool exact) {
    std::vector<std::string> argv = {VOX_RENDER_BIN, Store(), "-o", Path(name + ".exr"),
                                     "--stats", Path(name + ".json"), "--scene",
                                     Path("scene.json"), "--size", "192x192", "--threads", "2",
                                     "--quiet"};
    if (exact) argv.insert(argv.end(), {"--lod", "0"});
    return argv;
  }

  // The frame in kLimit, cold, against the same frame rendered without a limit.
  void RendersInTheBudget(bool exact) {
    VOX_REQUIRE_MEMORY_CGROUP();
    const std::string name = exact ? "exact" : "default";
    // The reference: the budget large enough for every brick at once.
    std::string reference;
    for (const std::string& a : RenderArgs(name + "_free", exact)) reference += a + " ";
    reference += "--memory-mb 2048";
    ASSERT_EQ(std::system(reference.c_str()), 0) << reference;

    CgroupRunOptions o;
    o.limit_bytes = kLimit;
    o.drop_page_cache = true;
    o.stderr_path = Path(name + ".log");
    auto r = RunInMemoryCgroup(RenderArgs(name, exact), o);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const std::string log = ReadAll(o.stderr_path);
    std::printf("%s frame in %llu MiB: %s\n", name.c_str(),
                (unsigned long long)(kLimit / kMiB), r->Describe().c_str());
    ASSERT_EQ(r->exit_code, 0) << r->Describe() << "\n" << log;
    EXPECT_FALSE(r->oom_killed) << r->Describe();
    EXPECT_EQ(r->failcnt, 0u) << r->Describe();
    EXPECT_LE(r->peak_bytes, kLimit) << r->Describe();

    const auto j = nlohmann::json::parse(ReadAll(Path(name + ".json")));
    const auto& mem = j["memory"];
    const auto& pool = mem["brick_pool"];
    const auto& cache = j["cache"];
    SCOPED_TRACE(mem.dump() + "\n" + cache.dump());
    EXPECT_EQ(mem["total"].get<uint64_t>(), kLimit);  // the budget is the cgroup's limit
    EXPECT_LE(mem["process"]["peak_rss"].get<uint64_t>(), kLimit);
    // Blocks of one density are charged: a 32^3 brick's largest charge has
    // its byte per voxel (32 KiB) beside its 128 KiB of densities.
    EXPECT_GE(mem["max_brick_bytes"].get<uint64_t>(), uint64_t(128 + 32) << 10);
    // The pool holds no more than the caches charged: it never had to evict
    // for room, nor overflowed to the heap.
    EXPECT_EQ(pool["overflows"].get<uint64_t>(), 0u);
    EXPECT_EQ(pool["reclaimed"].get<uint64_t>(), 0u);
    EXPECT_LE(pool["peak_in_use"].get<uint64_t>(), pool["capacity"].get<uint64_t>());
    if (exact) {
      // One store, one cache: every byte of the pool's blocks is charged.
      EXPECT_LE(pool["in_use"].get<uint64_t>(), cache["bytes_resident"].get<uint64_t>());
      // The decoded bricks are several times the cache: it turned over.
      EXPECT_GT(cache["evictions"].get<uint64_t>(), 1000u);
    }
    EXPECT_GT(j["rays"]["volume"].get<uint64_t>(), 0u);  // the shadows were traced
    std::printf("%s frame: peak RSS %.1f MiB, brick cache %.1f MiB, pool %.1f / %.1f MiB "
                "(peak in use / capacity), %llu bricks read, %llu evicted\n",
                name.c_str(), mem["process"]["peak_rss"].get<double>() / kMiB,
                mem["brick_cache"].get<double>() / kMiB, pool["peak_in_use"].get<double>() / kMiB,
                pool["capacity"].get<double>() / kMiB,
                (unsigned long long)cache["misses"].get<uint64_t>(),
                (unsigned long long)cache["evictions"].get<uint64_t>());

    // The same pixels as without a limit.
    auto tight = ReadExr(Path(name + ".exr"));
    auto free = ReadExr(Path(name + "_free.exr"));
    ASSERT_TRUE(tight.ok()) << tight.status().ToString();
    ASSERT_TRUE(free.ok()) << free.status().ToString();
    for (const char* c : {"R", "G", "B", "A"}) {
      ASSERT_EQ(tight->pixels.count(c), 1u) << c;
      EXPECT_EQ(tight->pixels[c], free->pixels[c]) << "channel " << c;
    }
    double alpha = 0;
    for (const float a : tight->pixels["A"]) alpha += a;
    EXPECT_GT(alpha, 0.1 * 192 * 192);  // the fog covers the frame's middle
  }

  static std::string* dir_;
};

std::string* FogBudgetCgroupTest::dir_ = nullptr;

TEST_F(FogBudgetCgroupTest, ExactFrameWithShadowsRendersIn80MiB) { RendersInTheBudget(true); }

TEST_F(FogBudgetCgroupTest, DefaultFrameWithShadowsRendersIn80MiB) { RendersInTheBudget(false); }

}  // namespace
}  // namespace vox::testing

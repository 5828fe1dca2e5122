// Level of detail by default: vox-render uses the pyramid when
// the store has one (--lod 0: the exact frame, bit for bit the frame of a
// store without one), says so in --stats and the EXR header, keeps close-ups
// exact, antialiases coarse silhouettes (fractional alpha nearer an exact
// 16-samples reference than whole dilated cells), does not depend on the
// tiling, and vox-merge refuses parts rendered with different settings.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "render/exr.h"
#include "render/job.h"
#include "storage/lod.h"
#include "core/util/memory_budget.h"
#include "tests/common/run_command.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

class LodDefault : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_lod_default_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    const StoreMeta meta = testing::TestMeta(7, GridClass::kLevelSet);  // 128^3, bricks of 8^3
    const std::vector<MemoryVoxel> voxels = testing::ShellVoxels(128, glm::dvec3(64), 38, 41);
    ASSERT_TRUE(testing::WriteStore(Path("store"), meta, voxels).ok());
    ASSERT_TRUE(testing::WriteStore(Path("nolod"), meta, voxels).ok());
    auto built = BuildLod(Path("store"), LodBuildOptions{});
    ASSERT_TRUE(built.ok()) << built.status().ToString();
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  // Render's jobs run over this session when set (vox-view's warm frames).
  static inline RenderSession* session_ = nullptr;

  // A view from `z` voxels in front of the shell's centre, `size`^2 pixels.
  static std::string CameraJson(double z, int size, double y = 64.5) {
    return "{\"position\":[64.5," + std::to_string(y) + "," + std::to_string(64.5 + z) +
           "],\"look_at\":[64.5,64.5,64.5],\"fov_deg\":40,\"width\":" + std::to_string(size) +
           ",\"height\":" + std::to_string(size) + "}";
  }
  static constexpr const char* kBlack = "{\"background\":[0,0,0]}";

  struct Frame {
    RenderJobOutput out;
    nlohmann::json stats;
  };
  static Frame Render(const std::string& store, const std::string& camera,
                      std::optional<double> lod, int grid = kDefaultSilhouetteGrid, int tile = 64,
                      const std::string& scene = kBlack, bool prefetch = false) {
    RenderJobOptions o;
    o.prefetch = prefetch;
    o.store_dir = Path(store);
    o.camera_json = camera;
    o.scene_json = scene;
    o.exr_path.clear();
    o.quiet = true;
    o.keep_image = true;
    o.threads = 2;
    o.tile_size = tile;
    o.lod = lod;
    o.silhouette_grid = grid;
    Frame f;
    const Status s = RunRenderJob(o, &f.out, session_);
    EXPECT_TRUE(s.ok()) << s.ToString();
    if (s.ok()) f.stats = nlohmann::json::parse(f.out.stats_json);
    return f;
  }
  static size_t Differences(const std::vector<float>& a, const std::vector<float>& b) {
    EXPECT_EQ(a.size(), b.size());
    size_t n = 0;
    for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
      n += std::memcmp(&a[i], &b[i], sizeof(float)) != 0;
    return n;
  }
  static void ExpectIdentical(const Frame& a, const Frame& b) {
    EXPECT_EQ(Differences(a.out.rgba, b.out.rgba), 0u);
    EXPECT_EQ(Differences(a.out.z, b.out.z), 0u);
  }
  // Root mean square difference of alpha.
  static double AlphaRmse(const Frame& a, const Frame& ref) {
    double sum = 0;
    const size_t n = a.out.rgba.size() / 4;
    for (size_t i = 0; i < n; ++i) {
      const double d = double(a.out.rgba[i * 4 + 3]) - double(ref.out.rgba[i * 4 + 3]);
      sum += d * d;
    }
    return std::sqrt(sum / double(n));
  }

  static fs::path* dir_;
};
fs::path* LodDefault::dir_ = nullptr;

// A far view: about 2.1 (front) to 2.6 (back) voxels a pixel, level 1.
const int kFarSize = 128;
const double kFarZ = 400;

TEST_F(LodDefault, OnByDefaultWhenTheStoreHasAPyramid) {
  const Frame f = Render("store", CameraJson(kFarZ, kFarSize), std::nullopt);
  EXPECT_EQ(f.stats["lod"]["factor"], 1.0);
  EXPECT_EQ(f.stats["lod"]["default"], true);
  EXPECT_EQ(f.stats["lod"]["setting"], "1 (default), silhouettes from 4x4 rays");
  EXPECT_GT(f.stats["lod"]["stops_by_level"]["1"].get<uint64_t>(), 0u);

  const Frame none = Render("nolod", CameraJson(kFarZ, kFarSize), std::nullopt);
  EXPECT_EQ(none.stats["lod"]["factor"], 0.0);
  EXPECT_EQ(none.stats["lod"]["setting"], "0 (exact: the store has no pyramid)");
  EXPECT_FALSE(none.stats["lod"].contains("stops_by_level"));

  const Frame exact = Render("store", CameraJson(kFarZ, kFarSize), 0.0);
  EXPECT_EQ(exact.stats["lod"]["factor"], 0.0);
  EXPECT_EQ(exact.stats["lod"]["default"], false);
  EXPECT_EQ(exact.stats["lod"]["setting"], "0 (exact)");
}

TEST_F(LodDefault, LodZeroIsTheExactFrameBitForBit) {
  // --lod 0 renders as if the store had no pyramid, and differs from the
  // default here (a far view, where coarse cells are visible).
  const Frame exact = Render("store", CameraJson(kFarZ, kFarSize), 0.0);
  const Frame nolod = Render("nolod", CameraJson(kFarZ, kFarSize), std::nullopt);
  ExpectIdentical(exact, nolod);
  const Frame lod = Render("store", CameraJson(kFarZ, kFarSize), std::nullopt);
  EXPECT_GT(Differences(exact.out.rgba, lod.out.rgba), 0u);
}

TEST_F(LodDefault, CloseUpIsBitIdenticalToTheExactFrame) {
  // At most 0.3 voxels a pixel up to the far side of the grid: every voxel
  // covers pixels, so the default frame is the exact one.
  const std::string close = CameraJson(75, 256, 80);
  const Frame lod = Render("store", close, std::nullopt);
  const Frame exact = Render("store", close, 0.0);
  ExpectIdentical(lod, exact);
  EXPECT_EQ(lod.stats["lod"]["refined_pixels"], 0u);
  EXPECT_EQ(lod.stats["lod"]["exact_rays"], lod.stats["rays"]["primary"]);
}

TEST_F(LodDefault, CoarseSilhouettesGetFractionalAlpha) {
  const std::string far = CameraJson(kFarZ, kFarSize);
  const Frame aa = Render("store", far, std::nullopt);
  const Frame whole = Render("store", far, std::nullopt, /*grid=*/0);
  const Frame exact = Render("store", far, 0.0);
  const Frame reference = Render("store", far, 0.0, kDefaultSilhouetteGrid, 64,
                                 "{\"background\":[0,0,0],\"samples_per_pixel\":16}");
  size_t fractional = 0, whole_fractional = 0;
  for (size_t i = 3; i < aa.out.rgba.size(); i += 4) {
    fractional += aa.out.rgba[i] > 0 && aa.out.rgba[i] < 1;
    whole_fractional += whole.out.rgba[i] > 0 && whole.out.rgba[i] < 1;
  }
  EXPECT_GT(fractional, 40u) << "the rim of a disc of ~36 pixels' radius";
  EXPECT_EQ(whole_fractional, 0u);
  EXPECT_GT(aa.stats["lod"]["refined_pixels"].get<uint64_t>(), 0u);
  EXPECT_EQ(aa.stats["lod"]["refine_rays"].get<uint64_t>(),
            16 * aa.stats["lod"]["refined_pixels"].get<uint64_t>());
  EXPECT_EQ(whole.stats["lod"]["refined_pixels"], 0u);
  const double aa_error = AlphaRmse(aa, reference), whole_error = AlphaRmse(whole, reference),
               exact_error = AlphaRmse(exact, reference);
  printf("alpha RMSE against 16 exact samples: antialiased %.4f, whole cells %.4f, exact %.4f; "
         "%zu fractional pixels, %llu refined\n",
         aa_error, whole_error, exact_error, fractional,
         (unsigned long long)aa.stats["lod"]["refined_pixels"].get<uint64_t>());
  EXPECT_LT(aa_error, whole_error);
  EXPECT_LT(aa_error, exact_error) << "coverage nearer the 16-sample truth than one exact sample";
}

TEST_F(LodDefault, TheTilingDoesNotChangeTheImage) {
  // The silhouette test looks at neighbours across tile borders: it traces
  // them again, so every tiling gives the same pixels.
  const std::string far = CameraJson(kFarZ, kFarSize);
  const Frame a = Render("store", far, std::nullopt, kDefaultSilhouetteGrid, 64);
  const Frame b = Render("store", far, std::nullopt, kDefaultSilhouetteGrid, 8);
  const Frame c = Render("store", far, std::nullopt, kDefaultSilhouetteGrid, 24);
  ExpectIdentical(a, b);
  ExpectIdentical(a, c);
  EXPECT_GT(b.stats["lod"]["border_rays"].get<uint64_t>(), 0u);
}

TEST_F(LodDefault, ReadingAheadReadsOnlyTheBricksTheRaysUse) {
  // --prefetch with the pyramid in effect pages in the base bricks the frame
  // needs (those of the antialiased silhouettes), as without it: its scout
  // traces the base store exactly, so it stays off (it read base bricks of
  // the whole front surface, which the coarse rays never enter).
  const std::string far = CameraJson(kFarZ, kFarSize);
  const Frame waiting = Render("store", far, std::nullopt, kDefaultSilhouetteGrid, 16);
  const Frame ahead = Render("store", far, std::nullopt, kDefaultSilhouetteGrid, 16, kBlack, true);
  ExpectIdentical(waiting, ahead);
  EXPECT_EQ(ahead.stats["memory"]["io_threads"].get<int>() > 0, true);
  EXPECT_EQ(ahead.stats["cache"]["bricks_paged_in"], waiting.stats["cache"]["bricks_paged_in"]);
  // Exact (--lod 0), the scout reads ahead the same bricks the rays enter.
  const Frame exact_waiting = Render("store", far, 0.0, kDefaultSilhouetteGrid, 16);
  const Frame exact_ahead = Render("store", far, 0.0, kDefaultSilhouetteGrid, 16, kBlack, true);
  ExpectIdentical(exact_waiting, exact_ahead);
  EXPECT_EQ(exact_ahead.stats["cache"]["bricks_paged_in"],
            exact_waiting.stats["cache"]["bricks_paged_in"]);
}

TEST_F(LodDefault, TheHeapIsWatchedDuringTheJobOnly) {
  // The frame's budget sets the heap watch's target: all but the headroom,
  // plus what this test process held before the job beyond the budget's
  // bare process. The job's end clears it: stores opened later are not watched.
  const Frame f = Render("store", CameraJson(kFarZ, kFarSize), std::nullopt);
  const nlohmann::json& m = f.stats["memory"];
  const uint64_t start = m["heap_watch"]["anon_at_start"], base = m["process_base"];
  EXPECT_GT(start, 0u);
  EXPECT_EQ(m["heap_watch"]["target"].get<uint64_t>(),
            m["total"].get<uint64_t>() - m["headroom"].get<uint64_t>() +
                (start > base ? start - base : 0));
  EXPECT_GT(m["process"]["rss_anon"].get<uint64_t>(), 0u);
  EXPECT_GE(m["process"]["peak_rss"].get<uint64_t>(), m["process"]["rss_anon"].get<uint64_t>());
  EXPECT_EQ(HeapWatch::Process().target(), 0u);
}

TEST_F(LodDefault, HeaderNamesTheSettingAndMergeRefusesMixedParts) {
  const std::string cam = Path("cam.json");
  {
    FILE* f = fopen(cam.c_str(), "w");
    ASSERT_NE(f, nullptr);
    fputs(CameraJson(kFarZ, kFarSize).c_str(), f);
    fclose(f);
  }
  const std::string render = std::string(VOX_RENDER_BIN) + " " + Path("store") + " --cam " + cam +
                             " --quiet --tiles ";
  testing::CommandResult r = testing::RunCommand(render + "1/2 -o " + Path("p1.exr"));
  ASSERT_EQ(r.code, 0) << r.output;
  r = testing::RunCommand(render + "2/2 --lod 0 -o " + Path("p2.exr"));
  ASSERT_EQ(r.code, 0) << r.output;
  r = testing::RunCommand(render + "2/2 -o " + Path("p2lod.exr"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto info = ReadExrInfo(Path("p1.exr"));
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->attrs["vox:lod"], "1 (default), silhouettes from 4x4 rays");
  info = ReadExrInfo(Path("p2.exr"));
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->attrs["vox:lod"], "0 (exact)");

  const std::string merge = std::string(VOX_MERGE_BIN) + " ";
  r = testing::RunCommand(merge + Path("p1.exr") + " " + Path("p2.exr") + " -o " +
                          Path("mixed.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("vox:lod"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(Path("mixed.exr")));
  r = testing::RunCommand(merge + Path("p1.exr") + " " + Path("p2lod.exr") + " -o " +
                          Path("whole.exr"));
  EXPECT_EQ(r.code, 0) << r.output;
}

// A RenderSession keeps the store, its pyramid and their caches open across
// jobs: a second identical frame reads no brick, and every frame, default or
// exact in any order, is bit for bit the frame of a job that opens the store.
TEST_F(LodDefault, SessionKeepsTheStoresWarmAndFramesTheSame) {
  const std::string far = CameraJson(400, 96), near = CameraJson(60, 64);
  const Frame fresh_default = Render("store", far, std::nullopt);
  const Frame fresh_exact = Render("store", near, 0.0);
  ASSERT_GT(fresh_default.stats["lod"]["bricks_paged_total"].get<uint64_t>(), 0u);
  RenderJobOptions o;
  o.store_dir = Path("store");
  o.threads = 2;
  auto session = OpenRenderSession(o);
  ASSERT_TRUE(session.ok()) << session.status().ToString();
  session_ = session->get();
  const Frame a = Render("store", far, std::nullopt);
  const Frame b = Render("store", far, std::nullopt);
  const Frame exact = Render("store", near, 0.0);
  const Frame exact_again = Render("store", near, 0.0);
  const Frame c = Render("store", far, std::nullopt);
  session_ = nullptr;
  EXPECT_GT(a.stats["lod"]["bricks_paged_total"].get<uint64_t>(), 0u);
  EXPECT_EQ(b.stats["lod"]["bricks_paged_total"].get<uint64_t>(), 0u);
  EXPECT_EQ(b.stats["cache"]["misses"].get<uint64_t>(), 0u);
  EXPECT_EQ(exact_again.stats["cache"]["misses"].get<uint64_t>(), 0u);
  EXPECT_EQ(exact.stats["lod"]["factor"].get<double>(), 0.0);
  EXPECT_EQ(b.stats["lod"]["factor"], fresh_default.stats["lod"]["factor"]);
  EXPECT_EQ(b.stats["timings"]["open_seconds"].get<double>(), 0.0);
  for (const Frame* f : {&a, &b, &c}) ExpectIdentical(*f, fresh_default);
  ExpectIdentical(exact, fresh_exact);
  ExpectIdentical(exact_again, fresh_exact);
}

}  // namespace
}  // namespace vox

// Level of detail (render/lod.h) over a real pyramid: a tiny factor and a
// close-up change nothing, LOD stops never come finer than the cone allows
// or later than the exact hit, a far view reads fewer bricks with the same
// silhouette, and vox-render's --lod errors name the flag (the default and
// antialiasing: lod_default_test).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <random>
#include <set>
#include <string>
#include <tuple>

#include "render/camera.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "storage/lod.h"
#include "tests/common/run_command.h"
#include "tests/render/render_util.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using Key = std::tuple<int64_t, int64_t, int64_t>;

class LodRender : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("vox_lod_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    StoreMeta meta = testing::TestMeta(7, GridClass::kLevelSet);  // 128^3, bricks of 8^3
    voxels_ = new std::vector<MemoryVoxel>(testing::ShellVoxels(128, glm::dvec3(64), 38, 41));
    // A thin plate inside, for rays that pass near occupied cells.
    for (uint64_t y = 50; y < 78; ++y)
      for (uint64_t x = 50; x < 78; x += 2) {
        MemoryVoxel v;
        v.x = x;
        v.y = y;
        v.z = 64;
        v.attr.normal = glm::vec3(0, 0, 1);
        voxels_->push_back(v);
      }
    ASSERT_TRUE(testing::WriteStore(Path("store"), meta, *voxels_).ok());
    ASSERT_TRUE(testing::WriteStore(Path("nolod"), meta, *voxels_).ok());
    auto st = BuildLod(Path("store"), LodBuildOptions{});
    ASSERT_TRUE(st.ok()) << st.status().ToString();
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete voxels_;
  }
  static std::string Path(const std::string& n) { return (*dir_ / n).string(); }

  void SetUp() override {
    OpenOptions oo;
    auto s = Store::Open(Path("store"), oo);
    ASSERT_TRUE(s.ok());
    base_ = std::move(s).value();
    auto p = LodPyramid::Open(Path("store"), *base_, oo);
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    pyramid_ = std::move(p).value();
    for (int l = 1; l <= pyramid_->max_level(); ++l) levels_.push_back(pyramid_->level(l));
  }

  StatusOr<std::unique_ptr<Renderer>> Make(const Camera& cam, double lod) {
    RenderOptions ro;
    ro.lod = lod;
    ro.silhouette_grid = 0;  // the stops themselves (lod_default_test: antialiasing)
    if (lod > 0) ro.lod_levels = levels_;
    return Renderer::Create(base_.get(), cam, Scene{}, ro);
  }

  static Camera Cam(glm::dvec3 pos, int size, Projection proj = Projection::kPerspective,
                    double ortho = 1.0) {
    Camera c;
    c.position = pos;
    c.look_at = glm::dvec3(64.5);
    c.fov_deg = 40;
    c.width = c.height = size;
    c.projection = proj;
    c.ortho_width = ortho;
    EXPECT_TRUE(c.Finalize().ok());
    return c;
  }

  void ExpectSameImage(const Camera& cam, double lod) {
    auto a = Make(cam, 0.0), b = Make(cam, lod);
    ASSERT_TRUE(a.ok() && b.ok());
    testing::Image ia, ib;
    RenderCounters ca, cb;
    ASSERT_TRUE(testing::RenderToMemory(**a, &ia, &ca).ok());
    ASSERT_TRUE(testing::RenderToMemory(**b, &ib, &cb).ok());
    for (const auto& [name, px] : ia.ch) {
      const auto& other = ib.ch.at(name);
      size_t diff = 0;
      for (size_t i = 0; i < px.size(); ++i)
        if (std::memcmp(&px[i], &other[i], sizeof(float)) != 0) ++diff;
      EXPECT_EQ(diff, 0u) << "channel " << name;
    }
    EXPECT_GT(ca.hit_pixels, 0u);
    EXPECT_EQ(cb.lod.exact_rays, cb.rays[kRayPrimary]) << "every primary ray stays at level 0";
  }

  static fs::path* dir_;
  static std::vector<MemoryVoxel>* voxels_;
  std::unique_ptr<Store> base_;
  std::unique_ptr<LodPyramid> pyramid_;
  std::vector<Volume*> levels_;
};
fs::path* LodRender::dir_ = nullptr;
std::vector<MemoryVoxel>* LodRender::voxels_ = nullptr;

TEST_F(LodRender, TinyFactorIsFullResolution) {
  // Far: 2 voxels a pixel; F = 1e-6 never leaves level 0.
  ExpectSameImage(Cam(glm::dvec3(64.5, 64.5, 64.5 + 400), 128), 1e-6);
}

TEST_F(LodRender, CloseUpWhereVoxelsCoverPixelsIsBitIdentical) {
  // Perspective: at most 0.3 voxels a pixel up to the far side of the grid.
  ExpectSameImage(Cam(glm::dvec3(64.5, 80, 64.5 + 75), 256), 1.0);
  // Orthographic: exactly a voxel a pixel.
  ExpectSameImage(Cam(glm::dvec3(64.5, 64.5, 300), 128, Projection::kOrthographic, 128.0), 1.0);
}

TEST_F(LodRender, FarViewReadsFewerBricksWithTheSameSilhouette) {
  // About 2.1 (front) to 2.6 (back) voxels a pixel: level 1; a disc of 36 pixels.
  const Camera cam = Cam(glm::dvec3(64.5, 64.5, 64.5 + 400), 128);
  auto a = Make(cam, 0.0), b = Make(cam, 1.0);
  ASSERT_TRUE(a.ok() && b.ok());
  const uint64_t base0 = base_->cache_stats().misses;
  testing::Image ia, ib;
  RenderCounters ca, cb;
  ASSERT_TRUE(testing::RenderToMemory(**a, &ia, &ca).ok());
  const uint64_t off_bricks = base_->cache_stats().misses - base0;
  const uint64_t base1 = base_->cache_stats().misses;
  uint64_t lod0 = 0;
  for (Volume* v : levels_) lod0 += v->cache_stats().misses;
  ASSERT_TRUE(testing::RenderToMemory(**b, &ib, &cb).ok());
  uint64_t lod_bricks = base_->cache_stats().misses - base1;
  for (Volume* v : levels_) lod_bricks += v->cache_stats().misses;
  lod_bricks -= lod0;
  EXPECT_LT(lod_bricks * 2, off_bricks) << lod_bricks << " vs " << off_bricks;
  uint64_t coarse = 0;
  for (int l = 1; l <= kMaxLevels; ++l) coarse += cb.lod.stops[l];
  EXPECT_GT(coarse, cb.hit_pixels / 2);
  EXPECT_EQ(cb.lod.stops[0] + coarse, cb.trace.hits) << "every hit counted at its level";
  // The finest level the memory budget keeps a cache for (FirstLevelSeen)
  // is never finer than a stop: here level 1, so the base gets no stop.
  glm::dvec3 lo, hi;
  WorldBounds(base_->meta(), &lo, &hi);
  const LodTracer& lt = *(*b)->lod();
  const int first = lt.FirstLevelSeen(cam, (*b)->PrimaryCone(), lo, hi);
  EXPECT_EQ(first, 1);
  for (int l = 0; l < first; ++l) EXPECT_EQ(cb.lod.stops[l], 0u) << "a stop at level " << l;
  const Camera close = Cam(glm::dvec3(64.5, 80, 64.5 + 75), 256);
  EXPECT_EQ(lt.FirstLevelSeen(close, PrimaryConeOf(close, base_->meta().voxel_size), lo, hi), 0)
      << "a close-up needs the base";
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < ia.ch.at("A").size(); ++i) {
    const bool x = ia.ch.at("A")[i] > 0, y = ib.ch.at("A")[i] > 0;
    inter += x && y;
    uni += x || y;
  }
  ASSERT_GT(uni, 0u);
  // Coarse cells are conservative: the disc grows by less than a cell (a pixel) at its rim.
  EXPECT_GE(double(inter) / double(uni), 0.9);
}

// Beam start distances with level of detail (RenderOptions::beam): primary
// rays start their level-0 segment's walk at the beam plane, and rays of a
// block the base meets nothing in still walk the coarse levels. Every
// channel is bit for bit what it is without the beam, antialiased
// silhouettes included, for less walk work.
TEST_F(LodRender, TheBeamChangesNoPixelOfALodFrame) {
  const std::vector<Camera> cams = {
      Cam(glm::dvec3(64.5, 64.5, 64.5 + 400), 128),  // far: level 1 and up
      Cam(glm::dvec3(64.5, 80, 64.5 + 75), 96),      // close: level 0
      Cam(glm::dvec3(200, 150, 300), 80),            // oblique, mixed levels
      Cam(glm::dvec3(64.5, 64.5, 300), 64, Projection::kOrthographic, 160.0),
      Cam(glm::dvec3(64.5, 64.5, 64.5 + 30), 64),    // inside the shell
      // Very far: 23 voxels a pixel, level 4 (cells wider than the base's
      // first-step cells): blocks whose beam meets nothing in the base
      // while a coarse cell's dilation reaches into them.
      Cam(glm::dvec3(64.5, 64.5, 64.5 + 1500), 48)};
  uint64_t cells_on = 0, cells_off = 0, coarse_stops = 0;
  for (size_t k = 0; k < cams.size(); ++k)
    for (int grid : {0, 4})
      for (int block : {8, 1}) {
      testing::Image img[2];
      RenderCounters counters[2];
      for (int beam = 0; beam < 2; ++beam) {
        RenderOptions ro;
        ro.lod = 1.0;
        ro.lod_levels = levels_;
        ro.silhouette_grid = grid;
        ro.beam = beam == 1;
        ro.beam_block = block;
        ro.layers.normal = ro.layers.voxel = true;
        auto r = Renderer::Create(base_.get(), cams[k], Scene{}, ro);
        ASSERT_TRUE(r.ok()) << r.status().ToString();
        ASSERT_TRUE(testing::RenderToMemory(**r, &img[beam], &counters[beam], 16).ok());
      }
      const std::string what = "camera " + std::to_string(k) + " grid " + std::to_string(grid) +
                               " block " + std::to_string(block);
      for (const auto& [name, px] : img[0].ch) {
        const auto& other = img[1].ch.at(name);
        ASSERT_EQ(px.size(), other.size());
        size_t diff = 0;
        for (size_t i = 0; i < px.size(); ++i)
          if (std::memcmp(&px[i], &other[i], sizeof(float)) != 0) ++diff;
        EXPECT_EQ(diff, 0u) << what << " channel " << name;
      }
      EXPECT_GT(counters[1].hit_pixels, 0u) << what;
      EXPECT_EQ(counters[0].lod.refined_pixels, counters[1].lod.refined_pixels) << what;
      cells_off += counters[0].trace.cells_visited;
      cells_on += counters[1].trace.cells_visited;
      for (int l = 1; l <= kMaxLevels; ++l) coarse_stops += counters[1].lod.stops[l];
      }
  EXPECT_GT(coarse_stops, 0u);  // the coarse levels were in play
  EXPECT_LT(cells_on, cells_off);
}

TEST_F(LodRender, StopsNeverFinerThanTheConeNorLaterThanTheExactHit) {
  auto lt = LodTracer::Create(base_.get(), levels_, 1.0);
  ASSERT_TRUE(lt.ok());
  auto base_tracer = LodLevelTracer::Create(base_->view(), DefaultFirstStepLevels(7));
  ASSERT_TRUE(base_tracer.ok());
  std::set<Key> occupied;
  for (const MemoryVoxel& v : *voxels_) occupied.insert({int64_t(v.x), int64_t(v.y), int64_t(v.z)});
  // A thread's own coarse tracers (a 2-slot table, so bricks are replaced
  // all the time) must give the shared tracers' answers.
  std::unique_ptr<LodThread> thread = lt->NewThread(1);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1), in(0, 128), cone(0, 0.2);
  int coarse = 0, checked = 0;
  for (int i = 0; i < 3000; ++i) {
    const glm::dvec3 dir = glm::normalize(glm::dvec3(u(rng), u(rng), u(rng)));
    const Ray r{glm::dvec3(in(rng), in(rng), in(rng)) - 150.0 * dir, dir};
    const Cone c{cone(rng) * 4, cone(rng) * (i % 3 == 0 ? 0.0 : 0.2)};
    LodSegment seg;
    auto f = lt->FirstHit(*base_tracer, nullptr, r, c, false, 0.0, &seg, nullptr);
    ASSERT_TRUE(f.ok());
    LodSegment seg_t;
    auto ft = lt->FirstHit(*base_tracer, thread.get(), r, c, false, 0.0, &seg_t, nullptr);
    ASSERT_TRUE(ft.ok());
    ASSERT_EQ(*ft, *f);
    if (*f) {
      EXPECT_EQ(seg_t.level, seg.level);
      EXPECT_EQ(seg_t.hit.voxel, seg.hit.voxel);
      EXPECT_EQ(seg_t.t0, seg.t0);
    }
    auto exact = base_tracer->FirstHit(r);
    ASSERT_TRUE(exact.ok());
    if (!*f) {
      EXPECT_FALSE(exact->has_value()) << "LOD missed what the exact ray hits";
      continue;
    }
    ++checked;
    const int l = seg.level;
    // Never finer than the voxels, never coarser than the cone allows.
    EXPECT_GE(l, 0);
    if (l > 0) {
      ++coarse;
      EXPECT_GE(1.0 * c.Width(seg.t0), std::ldexp(1.0, l) * (1 - 1e-9)) << "level " << l;
    }
    // The level the cone gives where the cell is entered (a segment's cells start in it).
    EXPECT_LE(l, lt->LevelForWidth(c.Width(seg.t0)));
    EXPECT_GE(l, lt->LevelForWidth(c.Width(seg.t0) * (1 - 1e-9)));
    // The cell holds an occupied voxel, and the ray is in it at t0.
    bool any = false;
    const int64_t s = int64_t(1) << l;
    for (int64_t z = 0; z < s && !any; ++z)
      for (int64_t y = 0; y < s && !any; ++y)
        for (int64_t x = 0; x < s && !any; ++x)
          any = occupied.count({seg.hit.voxel.x * s + x, seg.hit.voxel.y * s + y,
                                seg.hit.voxel.z * s + z}) > 0;
    EXPECT_TRUE(any) << "empty cell at level " << l;
    const glm::dvec3 p = r.origin + seg.t0 * r.dir;
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(p[a], double(seg.hit.voxel[a] * s) - 1e-6);
      EXPECT_LE(p[a], double((seg.hit.voxel[a] + 1) * s) + 1e-6);
    }
    // Coarse cells contain the exact hit's voxel: never seen later (a coarse
    // cell may be hit where the exact ray passes beside its voxels).
    if (!exact->has_value()) continue;
    EXPECT_LE(seg.t0, (*exact)->t + 1e-9);
    if (l == 0) {
      EXPECT_EQ(seg.hit.voxel, (*exact)->voxel);
      EXPECT_EQ(seg.t0, (*exact)->t);
    }
  }
  EXPECT_GT(coarse, 100);
  EXPECT_GT(checked, 1000);
}

using RunResult = testing::CommandResult;

TEST_F(LodRender, BadLodFlagsNameTheFlag) {
  const std::string bin = VOX_RENDER_BIN;
  const std::string out = " -o " + Path("x.exr") + " --size 16x16 --quiet";
  for (const char* bad : {"-1", "-0.5", "nan", "inf", "abc", "1e999", ""}) {
    RunResult r = testing::RunCommand(bin + " " + Path("store") + " --lod '" + bad + "'" + out);
    EXPECT_EQ(r.code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("--lod"), std::string::npos) << r.output;
  }
  RunResult r = testing::RunCommand(bin + " " + Path("nolod") + " --lod 1" + out);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("--lod"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--add-lod"), std::string::npos) << r.output;
  r = testing::RunCommand(bin + " " + Path("store") + " --lod 1" + out);
  EXPECT_EQ(r.code, 0) << r.output;
}

}  // namespace
}  // namespace vox

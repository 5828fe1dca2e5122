// Shadowed fog against independent truth: a box of uniform fog lit by one
// directional light, whose single scattering is an integral computed here
// (the light's path to each point leaves the box through a known face).
// The default quality (transmittance rays over the level-of-detail pyramid,
// the light evaluated every few voxels and interpolated) stays within 1% of
// the image's mean while walking far fewer cells than exact transmittance
// rays; the exact settings match the integral closely. And tiles, and
// vox-render --tiles parts merged by vox-merge, give the whole frame bit
// for bit.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "render/exr.h"
#include "render/renderer.h"
#include "storage/lod.h"
#include "tests/common/run_command.h"
#include "tests/render/render_util.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

// The fog: grid voxels [kLo, kHi) of a 64^3 grid of voxels of 1 world unit
// (voxel g covers world [g, g + 1)), density kDensity; the box's faces lie
// inside the pyramid's coarse cells, so coarse cells straddle them.
const glm::dvec3 kLo(9, 13, 11), kHi(51, 45, 53);
constexpr float kDensity = 0.8f;
constexpr double kAbsorption = 0.01, kScattering = 0.03;
const glm::dvec3 kLightDir = glm::normalize(glm::dvec3(-0.3, -1.0, -0.5));  // travel direction

Camera Cam() {
  Camera c;
  c.position = glm::dvec3(100, 80, 120);
  c.look_at = glm::dvec3(30, 29, 32);
  c.fov_deg = 40;
  c.width = 64;
  c.height = 56;
  EXPECT_TRUE(c.Finalize().ok());
  return c;
}

const char kLight[] = R"("lights":[{"type":"directional","direction":[-0.3,-1.0,-0.5],"shadows":true}])";

class FogTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("vox_fog_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    StoreMeta meta = testing::TestMeta(6, GridClass::kFogVolume);
    meta.brick_level = 3;
    meta.has_normal = false;
    // "store": the box of even density. "mottled": the same box whose voxels
    // alternate between two densities a part in 10^6 apart, so that no block
    // of voxels is of one density.
    for (const char* name : {"store", "mottled"}) {
      const bool mottled = std::string(name) == "mottled";
      std::vector<MemoryVoxel> voxels;
      for (int z = int(kLo.z); z < int(kHi.z); ++z)
        for (int y = int(kLo.y); y < int(kHi.y); ++y)
          for (int x = int(kLo.x); x < int(kHi.x); ++x) {
            MemoryVoxel v;
            v.x = uint64_t(x);
            v.y = uint64_t(y);
            v.z = uint64_t(z);
            v.attr.density = mottled && (x + y + z) % 2 ? kDensity * (1.0f + 1e-6f) : kDensity;
            voxels.push_back(v);
          }
      ASSERT_TRUE(testing::WriteStore(Path(name), meta, voxels).ok());
      auto st = BuildLod(Path(name), LodBuildOptions{});
      ASSERT_TRUE(st.ok()) << st.status().ToString();
    }
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& n) { return (*dir_ / n).string(); }
  static std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(Path(name)) << text;
    return Path(name);
  }

  void SetUp() override { Open("store"); }
  void Open(const std::string& name) {
    levels_.clear();
    pyramid_.reset();
    OpenOptions oo;
    auto s = Store::Open(Path(name), oo);
    ASSERT_TRUE(s.ok());
    base_ = std::move(s).value();
    auto p = LodPyramid::Open(Path(name), *base_, oo);
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    pyramid_ = std::move(p).value();
    for (int l = 1; l <= pyramid_->max_level(); ++l) levels_.push_back(pyramid_->level(l));
  }

  // Renders with the pyramid (lod > 0) or exactly; `volume`: the scene's
  // extra "volume" fields.
  testing::Image Render(double lod, const std::string& volume, RenderCounters* counters,
                        int tile = 16, double thickness = 1.0) {
    const std::string json = std::string("{") + light_ + R"(, "volume":{"absorption":)" +
                             std::to_string(kAbsorption * thickness) + R"(, "scattering":)" +
                             std::to_string(kScattering * thickness) + volume + "}}";
    auto scene = ParseScene(json, "fog scene");
    EXPECT_TRUE(scene.ok()) << scene.status().ToString();
    RenderOptions ro;
    ro.lod = lod;
    if (lod > 0) ro.lod_levels = levels_;
    testing::Image img;
    if (!scene.ok()) return img;
    auto r = Renderer::Create(base_.get(), Cam(), *scene, ro);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (!r.ok()) return img;
    EXPECT_TRUE((*r)->passes().scattering);
    Status s = testing::RenderToMemory(**r, &img, counters, tile);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return img;
  }

  static fs::path* dir_;
  std::string light_ = kLight;  // the scene's "lights"
  std::unique_ptr<Store> base_;
  std::unique_ptr<LodPyramid> pyramid_;
  std::vector<Volume*> levels_;
};
fs::path* FogTest::dir_ = nullptr;

// [t0, t1] of ray o + t d in the box [lo, hi] (t1 <= t0: a miss).
void Slab(const glm::dvec3& o, const glm::dvec3& d, double* t0, double* t1) {
  *t0 = 0;
  *t1 = 1e300;
  for (int a = 0; a < 3; ++a) {
    const double ta = (kLo[a] - o[a]) / d[a], tb = (kHi[a] - o[a]) / d[a];
    *t0 = std::max(*t0, std::min(ta, tb));
    *t1 = std::min(*t1, std::max(ta, tb));
  }
}

// The single scattering the pixel's ray gathers: the integral over its chord
// of T(entry, s) * sigma_s * rho * T(s, light), by the midpoint rule, for
// the coefficients times `thickness`, under a light travelling along
// light_dir.
double ExactScattering(const WorldRay& ray, double thickness, const glm::dvec3& light_dir) {
  double t0, t1;
  Slab(ray.origin, ray.dir, &t0, &t1);
  if (!(t1 > t0)) return 0.0;
  const double k = (kAbsorption + kScattering) * kDensity * thickness;
  const int n = 4000;
  const double h = (t1 - t0) / n;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double s = t0 + (i + 0.5) * h;
    double l0, l1;
    Slab(ray.origin + s * ray.dir, -light_dir, &l0, &l1);
    sum += std::exp(-k * (s - t0)) * std::exp(-k * std::max(0.0, l1));
  }
  return sum * h * kScattering * kDensity * thickness;
}

struct Error {
  double rmse_over_mean = 0, max_abs = 0, mean = 0;
  int covered = 0;
};

Error Compare(const testing::Image& img, double thickness = 1.0,
              const glm::dvec3& light_dir = kLightDir) {
  const Camera cam = Cam();
  Error e;
  double sq = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const double want = ExactScattering(cam.PixelRay(i + 0.5, j + 0.5), thickness, light_dir);
      const double got = img.at("R", i, j);
      if (want <= 0) continue;
      ++e.covered;
      e.mean += want;
      sq += (got - want) * (got - want);
      e.max_abs = std::max(e.max_abs, std::fabs(got - want));
    }
  e.mean /= std::max(1, e.covered);
  e.rmse_over_mean = std::sqrt(sq / std::max(1, e.covered)) / e.mean;
  return e;
}

TEST_F(FogTest, DefaultTransmittanceMatchesTheExactIntegral) {
  RenderCounters exact_c, default_c;
  const testing::Image exact =
      Render(0.0, R"(, "light_step":0.5, "shadow_lod":0, "light_lattice":false)", &exact_c);
  const testing::Image def = Render(1.0, "", &default_c);
  const Error e_exact = Compare(exact), e_def = Compare(def);
  EXPECT_GT(e_exact.covered, 1000);
  EXPECT_GT(e_exact.mean, 0.05);
  // Exact voxels and the light every half voxel: the integral itself.
  EXPECT_LT(e_exact.rmse_over_mean, 0.002) << "max " << e_exact.max_abs;
  // The default: within 1% of the mean.
  EXPECT_LT(e_def.rmse_over_mean, 0.01) << "max " << e_def.max_abs << " mean " << e_def.mean;
  EXPECT_LT(e_def.max_abs, 0.1 * e_def.mean);
  EXPECT_GT(default_c.rays[kRayVolume], 0u);
  // ... reading fewer densities than exact transmittance rays: coarse cells
  // on the light's path. (In the mottled box: in the even one both cross
  // blocks of one density whole, EvenBricksAreCrossedWhole.)
  Open("mottled");
  RenderCounters mottled_default_c, mottled_fine_c;
  Render(1.0, "", &mottled_default_c);
  Render(1.0, R"(, "shadow_lod":0)", &mottled_fine_c);
  Open("store");
  EXPECT_LT(mottled_default_c.attribute_lookups, mottled_fine_c.attribute_lookups);
}

// Thin fog, whose light is sampled far apart along each ray: the light is
// kept on a lattice shared by neighbouring pixels, which traces a fraction of
// the transmittance rays of evaluating it at every sample, for at most three
// quarters of a percent of the mean more error against the integral (1.5%
// against 1.1% here).
TEST_F(FogTest, ThinFogSharesTransmittanceRaysOnALattice) {
  constexpr double kThin = 0.2;
  RenderCounters lattice_c, samples_c;
  const Error e = Compare(Render(1.0, "", &lattice_c, 16, kThin), kThin);
  const Error e_samples =
      Compare(Render(1.0, R"(, "light_lattice":false)", &samples_c, 16, kThin), kThin);
  EXPECT_GT(e.covered, 1000);
  EXPECT_LT(e.rmse_over_mean, e_samples.rmse_over_mean + 0.0075)
      << "max " << e.max_abs << " mean " << e.mean << " against " << e_samples.rmse_over_mean;
  // (The samples' own rays, placed closer where the light bends: as the
  // exact frame's in SamplesAreCloserWhereTheLightBends.)
  EXPECT_LT(e_samples.rmse_over_mean, 0.0125)
      << "max " << e_samples.max_abs << " mean " << e_samples.mean;
  EXPECT_LT(e.rmse_over_mean, 0.025);
  EXPECT_GT(lattice_c.rays[kRayVolume], 0u);
  EXPECT_LT(lattice_c.rays[kRayVolume] * 2, samples_c.rays[kRayVolume])
      << lattice_c.rays[kRayVolume] << " against " << samples_c.rays[kRayVolume];
}

// The light as a directional light's string for the scene's "lights".
std::string DirectionalLight(const glm::dvec3& dir) {
  return R"("lights":[{"type":"directional","direction":[)" + std::to_string(dir.x) + "," +
         std::to_string(dir.y) + "," + std::to_string(dir.z) + R"(],"shadows":true}])";
}

// Lights from the side, one along an axis: the lattice's samples follow its
// spacing along the primary rays and come closer where the light bends, as
// samples that trace their own rays do, and the light between them follows
// its curvature, along the rays and across the light's columns (2.5% and
// 0.74% of the mean here; 3.7% and 1.6% interpolated straight in the
// light's logarithm; 6.2% and 2.7% with samples also spaced for their own
// rays and placed evenly).
TEST_F(FogTest, ThinFogOnALatticeUnderSideLights) {
  constexpr double kThin = 0.2;
  const struct {
    glm::dvec3 dir;
    double bound;
  } cases[] = {{glm::dvec3(1, 0, 0), 0.032}, {glm::dvec3(0.6, -0.6, 0.2), 0.011}};
  for (const auto& c : cases) {
    light_ = DirectionalLight(c.dir);
    RenderCounters rc;
    const Error e = Compare(Render(1.0, "", &rc, 16, kThin), kThin, glm::normalize(c.dir));
    EXPECT_GT(e.covered, 1000);
    EXPECT_LT(e.rmse_over_mean, c.bound)
        << "light along " << c.dir.x << "," << c.dir.y << "," << c.dir.z << ": max " << e.max_abs
        << " mean " << e.mean;
  }
}

// A light along an axis runs along the box's faces: a primary ray enters
// the fog on a face, where a transmittance ray walks the empty voxels
// beside the fog (a ray on a voxel face belongs to the voxels on its upper
// side). The light at a cell's entry is read just inside the cell, and the
// exact frame stays within 1% of the integral in thick fog (with the
// entry's own light: 4.1% along x, 0.9% along y).
TEST_F(FogTest, LightsAlongAnAxisMatchTheExactIntegral) {
  constexpr double kThick = 5.0;  // 0.16 optical depth per voxel
  for (const glm::dvec3 dir : {glm::dvec3(1, 0, 0), glm::dvec3(0, -1, 0)}) {
    light_ = DirectionalLight(dir);
    RenderCounters c;
    const Error e = Compare(
        Render(0.0, R"(, "light_step":0.5, "shadow_lod":0, "light_lattice":false)", &c, 16, kThick),
        kThick, dir);
    EXPECT_GT(e.covered, 1000);
    EXPECT_LT(e.rmse_over_mean, 0.01) << "light along " << dir.x << "," << dir.y << "," << dir.z
                                      << ": max " << e.max_abs << " mean " << e.mean;
  }
}

// Samples that trace their own rays are placed closer where the light's
// logarithm bends along the ray (where a ray crosses from the light's
// shadow of the box's edge into its open light): in thin fog, whose samples
// lie far apart, the exact frame stays within 1.25% of the integral (1.8%
// when they are not; the default frame without the lattice likewise, in
// ThinFogSharesTransmittanceRaysOnALattice).
TEST_F(FogTest, SamplesAreCloserWhereTheLightBends) {
  constexpr double kThin = 0.2;
  RenderCounters exact_c;
  const Error e_exact = Compare(Render(0.0, "", &exact_c, 16, kThin), kThin);
  EXPECT_GT(e_exact.covered, 1000);
  EXPECT_LT(e_exact.rmse_over_mean, 0.0125) << "max " << e_exact.max_abs << " mean " << e_exact.mean;
}

// One directional light: its light is kept on a lattice in light space,
// columns along the light each traced by one ray and sampled along their
// length, instead of on a lattice of points each tracing its own ray. The
// same light given as two lights of half its intensity takes the lattice
// of points: against the integral, the columns err as little, with a
// fraction of its rays per light.
TEST_F(FogTest, OneDirectionalLightIsKeptOnColumns) {
  constexpr double kThin = 0.2;
  RenderCounters columns_c, points_c;
  const Error e = Compare(Render(1.0, "", &columns_c, 16, kThin), kThin);
  const std::string half = R"({"type":"directional","direction":[-0.3,-1.0,-0.5],"intensity":0.5,"shadows":true})";
  light_ = R"("lights":[)" + half + "," + half + "]";
  const Error e_points = Compare(Render(1.0, "", &points_c, 16, kThin), kThin);
  EXPECT_GT(e.covered, 1000);
  EXPECT_LT(e.rmse_over_mean, e_points.rmse_over_mean + 0.001)
      << "max " << e.max_abs << " mean " << e.mean;
  EXPECT_LT(e.rmse_over_mean, 0.025);
  EXPECT_GT(columns_c.rays[kRayVolume], 0u);
  // (The lattice of points traces a ray per light from each point; the
  // columns, with those beside the blocks asked for, less than half that.)
  EXPECT_LT(columns_c.rays[kRayVolume] * 2, points_c.rays[kRayVolume] / 2)
      << columns_c.rays[kRayVolume] << " against " << points_c.rays[kRayVolume] << " for two lights";
}

// White lights in grey fog: the frame integrates one channel for three. A
// light whose blue is one part in 10^4 stronger takes the per-channel
// way, whose red and green are the same operations on the same values: the
// two frames' red and green agree bit for bit (as the image's floats hold
// them), for a light on the lattice in light space and for two on the
// lattice of points.
TEST_F(FogTest, GreyFramesIntegrateOneChannelForThree) {
  const std::string dir = R"("direction":[-0.3,-1.0,-0.5],"shadows":true)";
  for (int lights : {1, 2}) {
    testing::Image img[2];
    for (int tinted = 0; tinted < 2; ++tinted) {
      const std::string color = tinted ? "[1,1,1.0001]" : "[1,1,1]";
      std::string list = R"({"type":"directional",)" + dir + R"(,"color":)" + color + "}";
      if (lights == 2) list += R"(,{"type":"directional","direction":[0.5,-1.0,0.2],"shadows":true,"color":[1,1,1]})";
      light_ = R"("lights":[)" + list + "]";
      RenderCounters c;
      img[tinted] = Render(1.0, "", &c);
    }
    const Camera cam = Cam();
    int lit = 0, blue_differs = 0;
    for (int j = 0; j < cam.height; ++j)
      for (int i = 0; i < cam.width; ++i) {
        ASSERT_EQ(img[0].at("R", i, j), img[1].at("R", i, j)) << lights << " lights, pixel " << i << "," << j;
        ASSERT_EQ(img[0].at("G", i, j), img[1].at("G", i, j)) << lights << " lights, pixel " << i << "," << j;
        EXPECT_NEAR(img[0].at("B", i, j), img[1].at("B", i, j), 2e-4 * img[0].at("B", i, j) + 1e-12);
        lit += img[0].at("R", i, j) > 0;
        blue_differs += img[0].at("B", i, j) != img[1].at("B", i, j);
      }
    EXPECT_GT(lit, 1000);
    EXPECT_GT(blue_differs, 0) << "the tinted light changed nothing: the test compares a frame with itself";
  }
}

// Thick fog (about one optical depth per voxel): the light changes within a
// voxel, and a ray entering through thin fog must not carry its light into
// the thick fog behind it. The default stays within 1% of the integral.
TEST_F(FogTest, ThickFogStaysWithinOnePercent) {
  constexpr double kThick = 30.0;  // 1.0 optical depth per voxel
  RenderCounters c;
  const Error e = Compare(Render(1.0, "", &c, 16, kThick), kThick);
  EXPECT_GT(e.covered, 1000);
  EXPECT_LT(e.rmse_over_mean, 0.01) << "max " << e.max_abs << " mean " << e.mean;
}

// A block of voxels all of one density (a whole brick, or an aligned block
// inside one at the box's edges) is crossed as one cell, by primary and
// transmittance rays, exact or with the pyramid: the image is the one of
// walking its voxels (the mottled box's, where no two neighbours share a
// density), for a fraction of the density reads.
TEST_F(FogTest, EvenBricksAreCrossedWhole) {
  for (double lod : {0.0, 1.0}) {
    RenderCounters even_c, mottled_c;
    const std::string exact = lod > 0 ? "" : R"(, "shadow_lod":0)";
    const testing::Image even = Render(lod, exact, &even_c);
    Open("mottled");
    const testing::Image mottled = Render(lod, exact, &mottled_c);
    Open("store");
    double sq = 0, mean = 0;
    for (const auto& [name, px] : even.ch) {
      if (name != "R") continue;
      for (size_t i = 0; i < px.size(); ++i) {
        const double d = px[i] - mottled.ch.at(name)[i];
        sq += d * d;
        mean += px[i];
      }
      mean /= double(px.size());
      EXPECT_GT(mean, 0.01);
      EXPECT_LT(std::sqrt(sq / double(px.size())), 1e-4 * mean) << "lod " << lod;
    }
    EXPECT_GT(even_c.rays[kRayVolume], 0u);
    EXPECT_LT(even_c.attribute_lookups * 2, mottled_c.attribute_lookups)
        << even_c.attribute_lookups << " against " << mottled_c.attribute_lookups << ", lod " << lod;
  }
}

TEST_F(FogTest, TilesGiveTheWholeFrameBitForBit) {
  RenderCounters c;
  const testing::Image whole = Render(1.0, "", &c, 64);
  for (int tile : {5, 16}) {
    const testing::Image tiled = Render(1.0, "", &c, tile);
    for (const auto& [name, px] : whole.ch)
      EXPECT_EQ(std::memcmp(px.data(), tiled.ch.at(name).data(), px.size() * sizeof(float)), 0)
          << name << " with tiles of " << tile;
  }
  // vox-render's parts (--tiles I/N, as Slurm array tasks) merged by vox-merge.
  const std::string cam_json = Write(
      "cam.json", R"({"position":[100,80,120], "look_at":[30,29,32], "fov_deg":40, "width":64, "height":56})");
  const std::string scene = Write("scene.json", std::string("{") + kLight + "}");
  const std::string render = std::string(VOX_RENDER_BIN) + " " + Path("store") + " --cam " +
                             cam_json + " --scene " + scene + " --tile-size 16 --quiet ";
  auto full_run = testing::RunCommand(render + "-o " + Path("full.exr"));
  ASSERT_EQ(full_run.code, 0) << full_run.output;
  std::string parts;
  for (int i = 1; i <= 3; ++i) {
    const std::string p = Path("p" + std::to_string(i) + ".exr");
    auto r = testing::RunCommand(render + "-o " + p + " --threads 2 --tiles " + std::to_string(i) + "/3");
    ASSERT_EQ(r.code, 0) << r.output;
    parts += " " + p;
  }
  auto m = testing::RunCommand(std::string(VOX_MERGE_BIN) + parts + " -o " + Path("merged.exr") +
                               " --quiet");
  ASSERT_EQ(m.code, 0) << m.output;
  auto full = ReadExr(Path("full.exr"));
  auto merged = ReadExr(Path("merged.exr"));
  ASSERT_TRUE(full.ok() && merged.ok());
  EXPECT_GT(full->pixels["A"][size_t(28) * 64 + 32], 0.1f);
  for (const auto& [name, pixels] : full->pixels)
    EXPECT_EQ(std::memcmp(pixels.data(), merged->pixels[name].data(), pixels.size() * 4), 0)
        << name;
}

}  // namespace
}  // namespace vox

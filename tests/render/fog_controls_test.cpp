// Fog's shading controls (render/fog_material.h) against independent truth:
// the blackbody's colour against the CIE 1931 Planckian locus, the
// Henyey-Greenstein phase function against its normalisation and mean
// cosine, and renders of a box of uniform fog (density 0.8, temperature
// 1800 K) against integrals computed here: per-channel absorption and
// scattering, the density ramp, emission (constant and blackbody), and the
// brightness change forward scattering gives each pixel.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "render/fog_material.h"
#include "render/renderer.h"
#include "storage/lod.h"
#include "tests/render/render_util.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

const glm::dvec3 kLo(9, 13, 11), kHi(51, 45, 53);
constexpr float kDensity = 0.8f, kKelvin = 1800.0f;
const glm::dvec3 kLightDir = glm::normalize(glm::dvec3(-0.3, -1.0, -0.5));  // travel direction
const char kLight[] = R"("lights":[{"type":"directional","direction":[-0.3,-1.0,-0.5]}])";
// Exact voxels, the light every half voxel, no lattice: the integral itself.
const char kExact[] = R"("light_step":0.5, "shadow_lod":0, "light_lattice":false)";

TEST(FogMaterial, BlackbodyFollowsThePlanckianLocus) {
  // CIE 1931 chromaticity of the Planckian locus (Wyszecki and Stiles).
  struct {
    double kelvin, x, y;
  } locus[] = {{1500, 0.5857, 0.3931}, {2000, 0.5267, 0.4133}, {3000, 0.4369, 0.4041},
               {4000, 0.3805, 0.3768}, {6500, 0.3135, 0.3236}, {10000, 0.2807, 0.2883}};
  for (const auto& p : locus) {
    const glm::dvec3 xyz = BlackbodyXyz(p.kelvin);
    const double sum = xyz.x + xyz.y + xyz.z;
    // (the colour-matching fit's error: within 0.005 of the locus)
    EXPECT_NEAR(xyz.x / sum, p.x, 0.005) << p.kelvin;
    EXPECT_NEAR(xyz.y / sum, p.y, 0.005) << p.kelvin;
  }
  // Hotter is brighter; 6500 K is nearly sRGB's white; a flame is orange.
  EXPECT_LT(BlackbodyXyz(1000).y * 100, BlackbodyXyz(2000).y);
  const glm::dvec3 white = XyzToLinearSrgb(BlackbodyXyz(6500));
  EXPECT_NEAR(white.r / white.g, 1.0, 0.06);
  EXPECT_NEAR(white.b / white.g, 1.0, 0.06);
  const glm::dvec3 flame = XyzToLinearSrgb(BlackbodyXyz(1800));
  EXPECT_GT(flame.r, 2 * flame.g);
  EXPECT_GT(flame.g, 2 * flame.b);
  EXPECT_EQ(BlackbodyXyz(0).y, 0.0);
}

TEST(FogMaterial, HenyeyGreensteinIsNormalisedWithMeanCosineG) {
  for (double g : {-0.7, 0.0, 0.3, 0.9}) {
    // Over the sphere: 2 pi * integral over cos in [-1, 1], midpoint rule.
    const int n = 200000;
    double total = 0, mean_cos = 0;
    for (int i = 0; i < n; ++i) {
      const double c = -1.0 + (i + 0.5) * 2.0 / n;
      const double p = 2.0 * FogModel::kPi * HenyeyGreenstein(g, c) * 2.0 / n;
      total += p;
      mean_cos += c * p;
    }
    EXPECT_NEAR(total, 1.0, 1e-4) << g;
    EXPECT_NEAR(mean_cos, g, 1e-4) << g;
  }
  FogControls c;
  EXPECT_EQ(FogModel(c).Phase(0.3), 1.0);  // isotropic: the light unchanged
  c.phase_g = 0.5;
  EXPECT_NEAR(FogModel(c).Phase(1.0), 0.75 / std::pow(0.25, 1.5), 1e-12);
}

TEST(FogMaterial, RampInterpolatesAndBadControlsAreRefused) {
  auto s = ParseScene(R"({"volume":{"ramp":[{"density":0.2,"color":[1,0,0],"opacity":0},
                                             {"density":0.6,"color":[0,1,0],"opacity":2}]}})",
                      "s.json");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  FogModel m(s->volume);
  EXPECT_EQ(m.Opacity(0.1), 0.0);
  EXPECT_NEAR(m.Opacity(0.5), 1.5, 1e-12);
  EXPECT_EQ(m.Opacity(0.9), 2.0);
  EXPECT_NEAR(m.At(0.5, 0).scattering.r / m.At(0.5, 0).scattering.g, 1.0 / 3.0, 1e-12);
  // Emission through the ramp: intensity * colour * ramp colour * opacity.
  auto glow = ParseScene(
      R"({"volume":{"ramp":[{"density":0.2,"color":[1,0,0],"opacity":0},
                            {"density":0.6,"color":[0,1,0],"opacity":2}],
                    "emission":{"color":[1,1,0.5],"intensity":2,"ramp":true}}})",
      "s.json");
  ASSERT_TRUE(glow.ok()) << glow.status().ToString();
  const glm::dvec3 e = FogModel(glow->volume).At(0.5, 0).emission;
  EXPECT_NEAR(e.r, 2 * 0.25 * 1.5, 1e-12);
  EXPECT_NEAR(e.g, 2 * 0.75 * 1.5, 1e-12);
  EXPECT_EQ(e.b, 0.0);
  struct {
    const char* json;
    const char* field;
  } bad[] = {
      {R"({"volume":{"ramp":[{"density":0.5},{"density":0.5}]}})", "volume.ramp[1].density"},
      {R"({"volume":{"ramp":[]}})", "volume.ramp"},
      {R"({"volume":{"ramp":[{"opacity":1}]}})", "volume.ramp[0].density"},
      {R"({"volume":{"emission":{"ramp":true}}})", "volume.emission.ramp"},
      {R"({"volume":{"emission":{"colour":[1,1,1]}}})", "volume.emission.colour"},
      {R"({"volume":{"absorption":[1,-1,0]}})", "volume.absorption"},
      {R"({"volume":{"phase_g":1}})", "volume.phase_g"},
      {R"({"volume":{"blackbody":{"reference_kelvin":10}}})", "volume.blackbody.reference_kelvin"},
  };
  for (const auto& b : bad) {
    auto r = ParseScene(b.json, "s.json");
    ASSERT_FALSE(r.ok()) << b.json;
    EXPECT_NE(r.status().message().find(std::string("'") + b.field + "'"), std::string::npos)
        << r.status().ToString();
  }
  // The controls survive the scene's own JSON (written into EXR headers).
  auto again = ParseScene(s->ToJson(), "again.json");
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->volume.ramp.size(), 2u);
}

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

// [t0, t1] of ray o + t d in the box (t1 <= t0: a miss).
void Slab(const glm::dvec3& o, const glm::dvec3& d, double* t0, double* t1) {
  *t0 = 0;
  *t1 = 1e300;
  for (int a = 0; a < 3; ++a) {
    const double ta = (kLo[a] - o[a]) / d[a], tb = (kHi[a] - o[a]) / d[a];
    *t0 = std::max(*t0, std::min(ta, tb));
    *t1 = std::min(*t1, std::max(ta, tb));
  }
}

// Single scattering along the pixel's ray through fog of extinction `ext`
// and scattering `sca` per unit length (density included), lit by the
// directional light: the midpoint rule over the chord.
double ExactScattering(const WorldRay& ray, double ext, double sca) {
  double t0, t1;
  Slab(ray.origin, ray.dir, &t0, &t1);
  if (!(t1 > t0)) return 0.0;
  const int n = 4000;
  const double h = (t1 - t0) / n;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double s = t0 + (i + 0.5) * h;
    double l0, l1;
    Slab(ray.origin + s * ray.dir, -kLightDir, &l0, &l1);
    sum += std::exp(-ext * (s - t0)) * std::exp(-ext * std::max(0.0, l1));
  }
  return sum * h * sca;
}

// Emission j per unit length through extinction ext: j / ext (1 - e^-(ext chord)).
double ExactEmission(const WorldRay& ray, double ext, double j) {
  double t0, t1;
  Slab(ray.origin, ray.dir, &t0, &t1);
  if (!(t1 > t0)) return 0.0;
  return j / ext * -std::expm1(-ext * (t1 - t0));
}

class FogControlsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_fog_controls_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    StoreMeta meta = testing::TestMeta(6, GridClass::kFogVolume);
    meta.brick_level = 3;
    meta.has_normal = false;
    meta.has_temperature = true;
    std::vector<MemoryVoxel> voxels;
    for (int z = int(kLo.z); z < int(kHi.z); ++z)
      for (int y = int(kLo.y); y < int(kHi.y); ++y)
        for (int x = int(kLo.x); x < int(kHi.x); ++x) {
          MemoryVoxel v;
          v.x = uint64_t(x);
          v.y = uint64_t(y);
          v.z = uint64_t(z);
          v.attr.density = kDensity;
          v.attr.temperature = kKelvin;
          voxels.push_back(v);
        }
    ASSERT_TRUE(testing::WriteStore(Path(), meta, voxels).ok());
    auto st = BuildLod(Path(), LodBuildOptions{});
    ASSERT_TRUE(st.ok()) << st.status().ToString();
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path() { return (*dir_ / "store").string(); }

  void SetUp() override {
    auto s = Store::Open(Path(), OpenOptions{});
    ASSERT_TRUE(s.ok());
    base_ = std::move(s).value();
    auto p = LodPyramid::Open(Path(), *base_, OpenOptions{});
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    pyramid_ = std::move(p).value();
    for (int l = 1; l <= pyramid_->max_level(); ++l) levels_.push_back(pyramid_->level(l));
  }

  // `scene`: scene.json's text; lod > 0: with the pyramid.
  testing::Image Render(const std::string& scene, double lod = 0.0) {
    testing::Image img;
    auto s = ParseScene(scene, "scene.json");
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    if (!s.ok()) return img;
    RenderOptions ro;
    ro.lod = lod;
    if (lod > 0) ro.lod_levels = levels_;
    auto r = Renderer::Create(base_.get(), Cam(), *s, ro);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (!r.ok()) return img;
    RenderCounters c;
    Status st = testing::RenderToMemory(**r, &img, &c);
    EXPECT_TRUE(st.ok()) << st.ToString();
    return img;
  }

  // RMSE over the mean of `img`'s channel against want(ray) over the pixels
  // where want > 0 (at least 1000 of them, mean above `min_mean`).
  template <class Want>
  double Error(const testing::Image& img, const char* channel, Want&& want,
               double min_mean = 0.01) {
    const Camera cam = Cam();
    double sq = 0, mean = 0;
    int n = 0;
    for (int j = 0; j < cam.height; ++j)
      for (int i = 0; i < cam.width; ++i) {
        const double w = want(cam.PixelRay(i + 0.5, j + 0.5));
        if (w <= 0) continue;
        const double d = img.at(channel, i, j) - w;
        sq += d * d;
        mean += w;
        ++n;
      }
    EXPECT_GT(n, 1000);
    mean /= std::max(1, n);
    EXPECT_GT(mean, min_mean) << channel;
    return std::sqrt(sq / std::max(1, n)) / mean;
  }

  static fs::path* dir_;
  std::unique_ptr<Store> base_;
  std::unique_ptr<LodPyramid> pyramid_;
  std::vector<Volume*> levels_;
};
fs::path* FogControlsTest::dir_ = nullptr;

TEST_F(FogControlsTest, RgbAbsorptionAndScatteringActPerChannel) {
  const glm::dvec3 sa(0.01, 0.04, 0.002), ss(0.03, 0.01, 0.06);
  const testing::Image img = Render(std::string("{") + kLight +
                                    R"(, "volume":{"absorption":[0.01,0.04,0.002],
                                       "scattering":[0.03,0.01,0.06], )" +
                                    kExact + "}}");
  const char* names[] = {"R", "G", "B"};
  for (int k = 0; k < 3; ++k) {
    const double e = Error(img, names[k], [&](const WorldRay& r) {
      return ExactScattering(r, (sa[k] + ss[k]) * kDensity, ss[k] * kDensity);
    });
    EXPECT_LT(e, 0.003) << names[k];
  }
  // Each channel's alpha is its own transmittance: A is their mean.
  const Camera cam = Cam();
  double t0, t1;
  const WorldRay mid = cam.PixelRay(32.5, 28.5);
  Slab(mid.origin, mid.dir, &t0, &t1);
  ASSERT_GT(t1, t0);
  double want_a = 0;
  for (int k = 0; k < 3; ++k)
    want_a += (1.0 - std::exp(-(sa[k] + ss[k]) * kDensity * (t1 - t0))) / 3;
  EXPECT_NEAR(img.at("A", 32, 28), want_a, 2e-3);
}

TEST_F(FogControlsTest, RampMapsDensityToOpacityAndColour) {
  // At density 0.8: opacity 0.2 * 0 + 0.8 * 2 = 1.6, colour 0.2 c0 + 0.8 c1.
  const glm::dvec3 c0(1.0, 1.0, 1.0), c1(0.2, 0.5, 1.0);
  const glm::dvec3 tint = 0.2 * c0 + 0.8 * c1;
  const testing::Image img = Render(std::string("{") + kLight +
                                    R"(, "volume":{"absorption":0.01, "scattering":0.03,
                                       "ramp":[{"density":0,"color":[1,1,1],"opacity":0},
                                               {"density":1,"color":[0.2,0.5,1],"opacity":2}], )" +
                                    kExact + "}}");
  const char* names[] = {"R", "G", "B"};
  for (int k = 0; k < 3; ++k) {
    const double e = Error(img, names[k], [&](const WorldRay& r) {
      return tint[k] * ExactScattering(r, 0.04 * 1.6, 0.03 * 1.6);
    });
    EXPECT_LT(e, 0.003) << names[k];
  }
}

TEST_F(FogControlsTest, EmissionGlowsThroughItsOwnAbsorption) {
  const glm::dvec3 col(1.0, 0.5, 0.25);
  const char* names[] = {"R", "G", "B"};
  for (double lod : {0.0, 1.0}) {
    SCOPED_TRACE(lod > 0 ? "with the pyramid" : "exact");
    const testing::Image img = Render(
        R"({"lights":[], "volume":{"absorption":0.05, "scattering":0,
            "emission":{"color":[1,0.5,0.25], "intensity":0.2}}})",
        lod);
    for (int k = 0; k < 3; ++k) {
      const double e = Error(img, names[k], [&](const WorldRay& r) {
        return ExactEmission(r, 0.05 * kDensity, 0.2 * col[k] * kDensity);
      });
      EXPECT_LT(e, lod > 0 ? 0.01 : 1e-4) << names[k];
    }
  }
}

TEST_F(FogControlsTest, TemperatureGlowsAsABlackbody) {
  // kelvin_scale 2, offset -1800: the stored 1800 reads as 1800 K.
  const glm::dvec3 rgb =
      XyzToLinearSrgb(BlackbodyXyz(1800)) / BlackbodyXyz(1500).y * 0.5;  // intensity 0.5
  ASSERT_GT(rgb.r, 0.5);
  // With the pyramid its coarse cells keep their voxels' mean temperature.
  for (double lod : {0.0, 1.0}) {
    SCOPED_TRACE(lod > 0 ? "with the pyramid" : "exact");
    const testing::Image img = Render(
        R"({"lights":[], "volume":{"absorption":0.05, "scattering":0,
          "blackbody":{"intensity":0.5, "kelvin_scale":2, "kelvin_offset":-1800}}})",
        lod);
    const char* names[] = {"R", "G", "B"};
    for (int k = 0; k < 3; ++k) {
      if (!(rgb[k] > 0)) {  // outside sRGB's gamut (a flame has no blue): none
        for (float v : img.ch.at(names[k])) EXPECT_EQ(v, 0.0f) << names[k];
        continue;
      }
      const double e = Error(
          img, names[k],
          [&](const WorldRay& r) {
            return ExactEmission(r, 0.05 * kDensity, std::max(0.0, rgb[k]));
          },
          1e-4);
      EXPECT_LT(e, lod > 0 ? 0.01 : 1e-4) << names[k];
    }
  }
}

// With one directional light the phase function is constant along each ray:
// each pixel changes by exactly 4 pi HG(g, cos) for its ray's angle to the
// light (forward scattering brightens the pixels looking towards it). With
// two lights (each sample's lights weighted one by one) two halves of the
// light give the image of one.
TEST_F(FogControlsTest, ForwardScatteringBrightensEachPixelByItsPhase) {
  const std::string vol = R"("absorption":0.01, "scattering":0.03)";
  const testing::Image iso = Render(std::string("{") + kLight + ", \"volume\":{" + vol + "}}", 1.0);
  const testing::Image fwd =
      Render(std::string("{") + kLight + ", \"volume\":{" + vol + ", \"phase_g\":0.6}}", 1.0);
  const Camera cam = Cam();
  int n = 0;
  double max_rel = 0;
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const double a = iso.at("R", i, j);
      if (!(a > 1e-3)) continue;
      const WorldRay r = cam.PixelRay(i + 0.5, j + 0.5);
      const double cos_theta = glm::dot(kLightDir, -r.dir);  // light travel . towards camera
      const double want = (1 - 0.36) / std::pow(1 + 0.36 - 1.2 * cos_theta, 1.5);
      max_rel = std::max(max_rel, std::fabs(fwd.at("R", i, j) / a / want - 1.0));
      ++n;
    }
  EXPECT_GT(n, 1000);
  EXPECT_LT(max_rel, 1e-4);

  const std::string half = R"({"type":"directional","direction":[-0.3,-1.0,-0.5],"intensity":0.5})";
  const std::string g = std::string(", \"phase_g\":0.6, ") + kExact;
  const testing::Image one = Render(std::string("{") + kLight + ", \"volume\":{" + vol + g + "}}");
  const testing::Image two =
      Render(R"({"lights":[)" + half + "," + half + R"(], "volume":{)" + vol + g + "}}");
  double sq = 0, mean = 0;
  for (size_t p = 0; p < one.ch.at("R").size(); ++p) {
    const double d = one.ch.at("R")[p] - two.ch.at("R")[p];
    sq += d * d;
    mean += one.ch.at("R")[p];
  }
  EXPECT_GT(mean, 10.0);
  EXPECT_LT(std::sqrt(sq / one.ch.at("R").size()), 1e-5 * mean / one.ch.at("R").size() + 1e-6);
}

}  // namespace
}  // namespace vox

// Level sets' shading normals: interpolated between voxels ("normals":
// "smooth", the default) or each voxel's own ("flat"), checked against a
// sphere's exact normals; and no dark specks one voxel off the silhouettes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>

#include "render/renderer.h"
#include "tests/render/render_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

using testing::Image;
using testing::MakeVolume;
using testing::RenderToMemory;
using testing::Sphere;
using testing::TestMeta;

// A sphere of radius 26 voxels in a 64^3 grid, as a level set with the
// exact normal of each voxel's centre stored.
constexpr double kRadius = 26.0;
const glm::dvec3 kCentre(32.0);

struct Render {
  Image img;
  RenderCounters counters;
};

// The sphere close up from +z, lit from above (the light travels down and
// a little into the picture), shadows off, no ambient light.
Render RenderSphere(const char* normals) {
  auto vol = MakeVolume(TestMeta(6, GridClass::kLevelSet), {Sphere(kCentre, kRadius)});
  EXPECT_NE(vol, nullptr);
  Camera cam;
  cam.position = glm::dvec3(32.0, 40.0, 110.0);
  cam.look_at = glm::dvec3(32.0, 50.0, 32.0);
  cam.fov_deg = 30.0;
  cam.width = cam.height = 160;
  EXPECT_TRUE(cam.Finalize().ok());
  const std::string json =
      std::string(R"({"ambient":[0,0,0], "background":[0,0,0], "material":{"specular":0},)") +
      R"("lights":[{"type":"directional", "direction":[0,-1,-0.3], "shadows":false}],)" +
      R"("normals":")" + normals + R"("})";
  auto scene = ParseScene(json, "test scene");
  EXPECT_TRUE(scene.ok()) << scene.status().ToString();
  RenderOptions o;
  o.layers.normal = o.layers.position = o.layers.voxel = true;
  auto r = Renderer::Create(vol.get(), cam, *scene, o);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  Render out;
  Status s = RenderToMemory(**r, &out.img, &out.counters);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return out;
}

double Luma(const Image& img, int x, int y) {
  return (img.at("R", x, y) + img.at("G", x, y) + img.at("B", x, y)) / 3.0;
}
bool Covered(const Image& img, int x, int y) { return img.at("A", x, y) > 0.5f; }

// Covered pixels darker than a third of the mean of their covered
// neighbours (at least 3 of the 8): isolated dark pixels.
int DarkSpecks(const Image& img) {
  int specks = 0;
  for (int y = 1; y + 1 < img.height; ++y)
    for (int x = 1; x + 1 < img.width; ++x) {
      if (!Covered(img, x, y)) continue;
      double sum = 0;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if ((dx || dy) && Covered(img, x + dx, y + dy)) {
            sum += Luma(img, x + dx, y + dy);
            ++n;
          }
      if (n >= 3 && Luma(img, x, y) < sum / n / 3.0) ++specks;
    }
  return specks;
}

// The top silhouette faces the light: a voxel just past it, whose stored
// normal faces slightly away from the camera, must stay lit. Negating such a
// normal to face the viewer turned it into the sphere, away from the light.
TEST(SmoothNormalsTest, NoDarkSpecksAtSilhouettes) {
  for (const char* normals : {"smooth", "flat"}) {
    Render r = RenderSphere(normals);
    int covered = 0;
    for (int y = 0; y < r.img.height; ++y)
      for (int x = 0; x < r.img.width; ++x) covered += Covered(r.img, x, y);
    EXPECT_GT(covered, 5000) << normals;
    EXPECT_LT(covered, r.img.width * r.img.height - 2000) << normals;  // a silhouette in view
    EXPECT_EQ(DarkSpecks(r.img), 0) << normals;
  }
}

// Mean angle in degrees between each covered pixel's shading normal and the
// sphere's exact normal at the hit point, over pixels whose normal faces the
// camera (mirrored silhouette normals left out).
double MeanNormalError(const Image& img, const glm::dvec3& eye) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      if (!Covered(img, x, y)) continue;
      const glm::dvec3 p(img.at("P.X", x, y), img.at("P.Y", x, y), img.at("P.Z", x, y));
      const glm::dvec3 nn(img.at("N.X", x, y), img.at("N.Y", x, y), img.at("N.Z", x, y));
      const glm::dvec3 exact = glm::normalize(p - kCentre);
      if (glm::dot(exact, eye - p) < 0.2 * glm::length(eye - p)) continue;
      sum += std::acos(std::clamp(glm::dot(glm::normalize(nn), exact), -1.0, 1.0));
      ++n;
    }
  EXPECT_GT(n, 5000);
  return n ? sum / n * 180.0 / M_PI : 0.0;
}

// Flat: each pixel's normal is its voxel's stored one (the exact normal at
// the voxel's centre). Smooth: interpolated to the hit point, it is much
// closer to the exact normal there; the hit voxels are the same.
TEST(SmoothNormalsTest, SmoothNormalsFollowTheSurface) {
  const glm::dvec3 eye(32.0, 40.0, 110.0);
  Render flat = RenderSphere("flat");
  Render smooth = RenderSphere("smooth");
  for (int y = 0; y < flat.img.height; y += 7)
    for (int x = 0; x < flat.img.width; x += 7) {
      if (!Covered(flat.img, x, y)) continue;
      const glm::dvec3 v(flat.img.at("voxel.i", x, y), flat.img.at("voxel.j", x, y),
                         flat.img.at("voxel.k", x, y));
      const glm::dvec3 stored = glm::normalize(v + 0.5 - kCentre);
      const glm::dvec3 nn(flat.img.at("N.X", x, y), flat.img.at("N.Y", x, y),
                          flat.img.at("N.Z", x, y));
      if (glm::dot(stored, eye - (v + 0.5)) > 0) {
        EXPECT_NEAR(glm::dot(nn, stored), 1.0, 1e-4);
      }
    }
  for (const char* c : {"A", "Z", "voxel.i", "voxel.j", "voxel.k", "P.X", "P.Y", "P.Z"}) {
    const std::vector<float>& a = flat.img.ch.at(c);
    const std::vector<float>& b = smooth.img.ch.at(c);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << c;  // NaN: misses
  }
  const double e_flat = MeanNormalError(flat.img, eye);
  const double e_smooth = MeanNormalError(smooth.img, eye);
  printf("mean normal error: flat %.3f, smooth %.3f degrees\n", e_flat, e_smooth);
  EXPECT_LT(e_smooth, 0.5 * e_flat);
  EXPECT_GT(smooth.counters.attribute_lookups, flat.counters.attribute_lookups);
}

TEST(SmoothNormalsTest, SceneField) {
  auto s = ParseScene(R"({"normals":"flat"})", "s.json");
  ASSERT_TRUE(s.ok());
  EXPECT_FALSE(s->smooth_normals);
  EXPECT_TRUE(ParseScene("{}", "s.json")->smooth_normals);
  auto back = ParseScene(s->ToJson(), "again");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_FALSE(back->smooth_normals);
  auto bad = ParseScene(R"({"normals":"phong"})", "s.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find("s.json"), std::string::npos);
  EXPECT_NE(bad.status().ToString().find("'smooth' or 'flat'"), std::string::npos);
}

}  // namespace
}  // namespace vox

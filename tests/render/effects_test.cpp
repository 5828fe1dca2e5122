// One test per effect on small generated scenes, checked against geometry
// computed independently of the renderer.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "render/renderer.h"
#include "tests/render/render_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

using testing::Box;
using testing::Image;
using testing::MakeVolume;
using testing::Part;
using testing::RenderToMemory;
using testing::Sphere;
using testing::TestMeta;

Camera Ortho(glm::dvec3 pos, glm::dvec3 at, glm::dvec3 up, double width_world, int w, int h) {
  Camera c;
  c.projection = Projection::kOrthographic;
  c.position = pos;
  c.look_at = at;
  c.up = up;
  c.ortho_width = width_world;
  c.width = w;
  c.height = h;
  EXPECT_TRUE(c.Finalize().ok());
  return c;
}

Camera Persp(glm::dvec3 pos, glm::dvec3 at, double fov, int w, int h) {
  Camera c;
  c.position = pos;
  c.look_at = at;
  c.fov_deg = fov;
  c.width = w;
  c.height = h;
  EXPECT_TRUE(c.Finalize().ok());
  return c;
}

Scene ParseOrDie(const char* json) {
  auto s = ParseScene(json, "test scene");
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? *s : Scene();
}

// A slab [8,24) x [8,24) x [8,10) whose normals all face +z.
Part Slab() {
  Part p = Box({8, 8, 8}, {24, 24, 10});
  p.normal = [](const glm::dvec3&) { return glm::dvec3(0, 0, 1); };
  return p;
}

struct Rendered {
  Image img;
  RenderCounters counters;
  RenderPasses passes;
};

Rendered Render(Volume* vol, const Camera& cam, const Scene& scene, int n1 = 0,
                ImageLayers layers = {}) {
  RenderOptions o;
  o.n1 = n1;
  o.layers = layers;
  auto r = Renderer::Create(vol, cam, scene, o);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  Rendered out;
  if (!r.ok()) return out;
  Status s = RenderToMemory(**r, &out.img, &out.counters);
  EXPECT_TRUE(s.ok()) << s.ToString();
  out.passes = (*r)->passes();
  return out;
}

int CountAlpha(const Image& img, float value) {
  int n = 0;
  for (float a : img.ch.at("A")) n += a == value;
  return n;
}

TEST(EffectsTest, PrimaryVisibilityMatchesTheBoxExactly) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Box({8, 8, 8}, {24, 24, 24})});
  ASSERT_TRUE(vol);
  Camera cam = Ortho({16, 16, 30}, {16, 16, 0}, {0, 1, 0}, 32, 32, 32);
  Rendered r = Render(vol.get(), cam, ParseOrDie(R"({"lights":[], "background":[0.2,0.3,0.4]})"));
  for (int j = 0; j < 32; ++j)
    for (int i = 0; i < 32; ++i) {
      // Pixel (i, j) looks down at world x = i + 0.5, y = 31.5 - j.
      bool inside = i >= 8 && i < 24 && (31 - j) >= 8 && (31 - j) < 24;
      float a = r.img.at("A", i, j);
      ASSERT_EQ(a, inside ? 1.0f : 0.0f) << i << "," << j;
      if (inside) {
        EXPECT_NEAR(r.img.at("Z", i, j), 6.0, 1e-9);  // camera plane z=30, box top z=24
      } else {
        EXPECT_TRUE(std::isinf(r.img.at("Z", i, j)));
        // Premultiplied: a miss is 0, 0, 0, 0 (the background is the preview's).
        EXPECT_EQ(r.img.at("R", i, j), 0.0f);
        EXPECT_EQ(r.img.at("G", i, j), 0.0f);
        EXPECT_EQ(r.img.at("B", i, j), 0.0f);
      }
    }
  EXPECT_EQ(r.counters.hit_pixels, 256u);
  EXPECT_EQ(r.counters.rays[kRayPrimary], 32u * 32u);
  // Unlit and uncoloured: no attribute is read.
  EXPECT_EQ(r.counters.attribute_lookups, 0u);
}

TEST(EffectsTest, NoShadowRaysWithoutShadowCastingLights) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Sphere({16, 16, 16}, 9)});
  ASSERT_TRUE(vol);
  Camera cam = Persp({16, 16, 60}, {16, 16, 16}, 30, 32, 32);
  for (const char* scene :
       {R"({"lights":[]})",
        R"({"lights":[{"type":"directional","direction":[0,0,-1],"shadows":false}]})",
        R"({"lights":[{"type":"point","position":[0,40,40],"shadows":false}]})"}) {
    Rendered r = Render(vol.get(), cam, ParseOrDie(scene));
    EXPECT_FALSE(r.passes.shadows) << scene;
    EXPECT_GT(r.counters.hit_pixels, 100u);
    EXPECT_EQ(r.counters.rays[kRayShadow], 0u) << scene;
    EXPECT_EQ(r.counters.rays[kRayReflection] + r.counters.rays[kRayRefraction] +
                  r.counters.rays[kRayVolume],
              0u);
    // Only primary rays were traversed.
    EXPECT_EQ(r.counters.trace.rays, r.counters.rays[kRayPrimary]);
  }
}

TEST(EffectsTest, ExactlyOneShadowRayPerLitHitPixel) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Slab()});
  ASSERT_TRUE(vol);
  Camera cam = Ortho({16, 16, 30}, {16, 16, 0}, {0, 1, 0}, 32, 32, 32);
  // The light comes from the camera's side: every hit is lit. Flat normals:
  // one attribute look-up per hit (smooth ones read the neighbours' too).
  Rendered r = Render(vol.get(), cam,
                      ParseOrDie(R"({"lights":[{"type":"directional","direction":[0.2,0.1,-1]},
                                               {"type":"point","position":[16,16,50],"shadows":false}],
                                    "normals":"flat"})"));
  EXPECT_TRUE(r.passes.shadows);
  EXPECT_EQ(CountAlpha(r.img, 1.0f), 256);
  EXPECT_EQ(r.counters.hit_pixels, 256u);
  EXPECT_EQ(r.counters.rays[kRayShadow], 256u);
  EXPECT_EQ(r.counters.attribute_lookups, 256u);  // one normal per hit
  // A light behind the slab lights nothing: no shadow rays at all.
  Rendered back = Render(vol.get(), cam,
                         ParseOrDie(R"({"lights":[{"type":"directional","direction":[0,0,1]}]})"));
  EXPECT_TRUE(back.passes.shadows);
  EXPECT_EQ(back.counters.rays[kRayShadow], 0u);
}

TEST(EffectsTest, PointLightsFallOffWithTheSquareOfTheDistance) {
  // The slab's top (z = 10, normal +z) seen from above, a point light straight
  // above pixel (16, 16) at heights 10 and 20 over the surface: the diffuse
  // light there is a quarter at twice the distance, and the same with
  // "falloff": "none".
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Slab()});
  ASSERT_TRUE(vol);
  Camera cam = Ortho({16.5, 16.5, 30}, {16.5, 16.5, 0}, {0, 1, 0}, 32, 33, 33);
  auto lit = [&](double height, const char* falloff) {
    const std::string json =
        R"({"ambient":[0,0,0], "material":{"specular":0}, "lights":[{"type":"point","position":[16.5,16.5,)" +
        std::to_string(10 + height) + R"(],"intensity":50,"shadows":false)" + falloff + "}]}";
    Rendered r = Render(vol.get(), cam, ParseOrDie(json.c_str()));
    EXPECT_EQ(r.img.at("A", 16, 16), 1.0f);
    return double(r.img.at("R", 16, 16));
  };
  const double near = lit(10, ""), far = lit(20, "");
  EXPECT_GT(near, 0.05);
  EXPECT_LT(near, 0.9);
  EXPECT_NEAR(far / near, 0.25, 0.02);
  EXPECT_NEAR(lit(20, R"(,"falloff":"none")"), lit(10, R"(,"falloff":"none")"), 1e-6);
}

TEST(EffectsTest, ShadowFallsWhereGeometrySays) {
  // Floor y in [0,4), a cube [12,20)^3 above it, light travelling along (1,-1,0):
  // the cube's shadow on the floor top (y = 4) covers x in [20,36), z in [12,20).
  Part floor = Box({0, 0, 0}, {32, 4, 32});
  floor.normal = [](const glm::dvec3&) { return glm::dvec3(0, 1, 0); };
  auto vol =
      MakeVolume(TestMeta(5, GridClass::kLevelSet), {floor, Box({12, 12, 12}, {20, 20, 20})});
  ASSERT_TRUE(vol);
  // Looking straight down; pixel (i, j) sees world x = i + 0.5, z = j + 0.5.
  Camera cam = Ortho({16, 30, 16}, {16, 0, 16}, {0, 0, -1}, 32, 32, 32);
  Rendered r =
      Render(vol.get(), cam, ParseOrDie(R"({"lights":[{"type":"directional","direction":[1,-1,0]}],
                                     "ambient":[0.1,0.1,0.1],
                                     "material":{"color":[1,1,1],"diffuse":1,"specular":0}})"));
  const float dark = 0.1f, lit = float(0.1 + std::sqrt(0.5));
  int checked = 0;
  for (int j = 0; j < 32; ++j)
    for (int i = 0; i < 32; ++i) {
      const double x = i + 0.5, z = j + 0.5;
      if (x >= 12 && x < 20 && z >= 12 && z < 20) continue;  // the cube's top
      const bool deep_shadow = x > 22 && z > 14 && z < 18;
      const bool clearly_lit = z < 10 || z > 22 || x < 10;
      if (deep_shadow) {
        EXPECT_NEAR(r.img.at("R", i, j), dark, 1e-6) << i << "," << j;
        ++checked;
      } else if (clearly_lit) {
        EXPECT_NEAR(r.img.at("R", i, j), lit, 1e-6) << i << "," << j;
        ++checked;
      }
    }
  EXPECT_GT(checked, 500);
}

TEST(EffectsTest, NoShadowAcneOnATiltedVoxelPlaneAtGrazingLight) {
  // A 3-voxel-thick slab under a tilted plane (a staircase of voxels), lit at
  // 4 degrees above the plane: nothing occludes it, so every hit pixel
  // must get the same, fully lit, shade.
  const glm::dvec3 n = glm::normalize(glm::dvec3(0.3, 1.0, 0.2));
  const glm::dvec3 p0(16, 14, 16);
  Part plane;
  plane.inside = [=](const glm::dvec3& c) {
    double d = glm::dot(c - p0, n);
    return d <= 0 && d > -3;
  };
  plane.normal = [=](const glm::dvec3&) { return n; };
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {plane});
  ASSERT_TRUE(vol);
  // Travel direction with n . (-dir) = sin(4 degrees).
  glm::dvec3 t = glm::normalize(glm::cross(n, glm::dvec3(0, 0, 1)));
  glm::dvec3 to_light = std::sin(4 * M_PI / 180) * n + std::cos(4 * M_PI / 180) * t;
  char json[512];
  snprintf(json, sizeof json,
           R"({"lights":[{"type":"directional","direction":[%.17g,%.17g,%.17g]}],
               "ambient":[0.1,0.1,0.1], "material":{"color":[1,1,1],"diffuse":1,"specular":0}})",
           -to_light.x, -to_light.y, -to_light.z);
  Camera cam = Ortho({16, 30, 16}, {16, 0, 16}, {0, 0, -1}, 20, 40, 40);
  Rendered r = Render(vol.get(), cam, ParseOrDie(json));
  const float lit = float(0.1 + glm::dot(n, to_light));
  int hits = 0;
  for (int j = 0; j < 40; ++j)
    for (int i = 0; i < 40; ++i) {
      if (r.img.at("A", i, j) != 1.0f) continue;
      ++hits;
      ASSERT_NEAR(r.img.at("R", i, j), lit, 1e-6) << i << "," << j;
    }
  EXPECT_EQ(hits, 1600);
  EXPECT_EQ(r.counters.rays[kRayShadow], 1600u);
}

TEST(EffectsTest, MirrorShowsTheReflectedObject) {
  // A mirror floor y in [0,4) and a red sphere above it; everything else diffuse.
  Part floor = Box({0, 0, 0}, {32, 4, 32}, glm::vec3(1.0f));
  floor.normal = [](const glm::dvec3&) { return glm::dvec3(0, 1, 0); };
  const glm::dvec3 c(16, 12, 10);
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet),
                        {floor, Sphere(c, 5, glm::vec3(1, 0, 0))}, /*has_color=*/true);
  ASSERT_TRUE(vol);
  Camera cam = Persp({16, 10, 40}, {16, 5, 16}, 50, 64, 64);
  Rendered r =
      Render(vol.get(), cam,
             ParseOrDie(R"({"lights":[{"type":"directional","direction":[0,-1,-1],"shadows":false}],
                                     "background":[0.2,0.4,0.8],
                                     "material":{"specular":0},
                                     "materials":[{"box":{"min":[-1,-1,-1],"max":[33,4.001,33]},
                                                   "reflect":1,"diffuse":0,"specular":0}]})"));
  EXPECT_TRUE(r.passes.reflection);
  EXPECT_FALSE(r.passes.refraction);
  EXPECT_GT(r.counters.rays[kRayReflection], 0u);
  // The sphere centre's mirror image, projected into the image.
  const glm::dvec3 mirrored(c.x, 8 - c.y, c.z);
  glm::dvec3 d = mirrored - cam.position;
  double zc = glm::dot(d, cam.forward());
  double t = std::tan(cam.fov_deg * M_PI / 360);
  int i = int((glm::dot(d, cam.right()) / zc / t + 1) / 2 * cam.width);
  int j = int((1 - glm::dot(d, cam.true_up()) / zc / t) / 2 * cam.height);
  ASSERT_TRUE(i >= 0 && i < 64 && j >= 0 && j < 64);
  // That pixel's ray hits the floor, not the sphere: check the depth.
  glm::dvec3 dir = cam.PixelRay(i + 0.5, j + 0.5).dir;
  double t_floor = (4 - cam.position.y) / dir.y;
  EXPECT_NEAR(r.img.at("Z", i, j), t_floor, 2.0);
  EXPECT_GT(r.img.at("R", i, j), 0.1f);
  EXPECT_EQ(r.img.at("G", i, j), 0.0f);
  EXPECT_EQ(r.img.at("B", i, j), 0.0f);
  // Near the bottom of the image the mirror shows the sky.
  EXPECT_NEAR(r.img.at("B", 32, 62), 0.8f, 1e-6);
  EXPECT_NEAR(r.img.at("G", 32, 62), 0.4f, 1e-6);
}

TEST(EffectsTest, ReflectionDepthIsRespected) {
  // A closed box of mirrors with the camera inside: every ray bounces until the
  // depth limit. No normals stored: the renderer uses the voxel faces.
  Part shell;
  shell.inside = [](const glm::dvec3& q) {
    auto in = [&](double lo, double hi) {
      return q.x >= lo && q.y >= lo && q.z >= lo && q.x <= hi && q.y <= hi && q.z <= hi;
    };
    return in(4, 28) && !in(5, 27);
  };
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {shell});
  ASSERT_TRUE(vol);
  Camera cam = Persp({16.2, 15.7, 16.1}, {3, 11, 2}, 90, 16, 16);
  for (int depth = 0; depth <= 3; ++depth) {
    std::string json =
        R"({"lights":[], "material":{"reflect":1,"diffuse":0,"specular":0}, "max_depth":)" +
        std::to_string(depth) + "}";
    Rendered r = Render(vol.get(), cam, ParseOrDie(json.c_str()));
    EXPECT_EQ(r.passes.reflection, depth > 0);
    EXPECT_EQ(r.counters.hit_pixels, 256u);
    EXPECT_EQ(r.counters.rays[kRayReflection], 256u * depth) << "max_depth " << depth;
    EXPECT_EQ(r.counters.trace.hits, 256u * (depth + 1));
  }
}

TEST(EffectsTest, GlassSphereInvertsTheBackground) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Sphere({16, 16, 16}, 12)});
  ASSERT_TRUE(vol);
  Camera cam = Persp({16, 16, 120}, {16, 16, 16}, 16, 64, 64);
  Rendered r = Render(vol.get(), cam,
                      ParseOrDie(R"({"lights":[], "background":{"top":[1,0,0],"bottom":[0,0,1]},
                                     "background_in_exr":true, "material":{"transmit":1,"diffuse":0,"specular":0,"ior":1.5}})"));
  EXPECT_TRUE(r.passes.refraction);
  EXPECT_FALSE(r.passes.reflection);
  EXPECT_GT(r.counters.rays[kRayRefraction], 0u);
  // Sphere radius on screen: 12 / (104 tan 8deg) * 32 = ~26 pixels around the centre.
  int inverted = 0, total = 0;
  for (int j = 0; j < 64; ++j)
    for (int i = 0; i < 64; ++i) {
      double dx = i + 0.5 - 32, dy = 32 - (j + 0.5);
      double rr = std::sqrt(dx * dx + dy * dy);
      float red = r.img.at("R", i, j), blue = r.img.at("B", i, j);
      if (rr > 29) {
        // Outside: the background as it is, red above, blue below.
        if (std::fabs(dy) > 20) {
          EXPECT_EQ(red > blue, dy > 0) << i << "," << j;
        }
      } else if (rr < 20 && std::fabs(dy) > 8) {
        ASSERT_EQ(r.img.at("A", i, j), 1.0f);
        ++total;
        inverted += (red > blue) == (dy < 0);
      }
    }
  EXPECT_GT(total, 200);
  EXPECT_EQ(inverted, total);
}

double ChordLength(const glm::dvec3& o, const glm::dvec3& d, glm::dvec3 lo, glm::dvec3 hi) {
  double t0 = 0, t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  return t1 > t0 ? t1 - t0 : 0.0;
}

TEST(EffectsTest, FogCubeTransmittanceIsExponential) {
  // Voxels of 0.5 world units; the cube is world [4,12)^3 with density 0.8.
  Part cube = Box({4, 4, 4}, {12, 12, 12});
  cube.density = 0.8f;
  auto vol = MakeVolume(TestMeta(5, GridClass::kFogVolume, 0.5), {cube});
  ASSERT_TRUE(vol);
  Camera cam = Persp({9, 10.5, 25}, {8, 8, 8}, 40, 48, 48);
  Rendered r = Render(
      vol.get(), cam,
      ParseOrDie(
          R"({"lights":[], "background":[1,1,1], "background_in_exr":true,
              "volume":{"absorption":0.3,"scattering":0}})"));
  EXPECT_TRUE(r.passes.volume);
  EXPECT_FALSE(r.passes.shading);
  EXPECT_FALSE(r.passes.scattering);
  EXPECT_EQ(r.counters.rays[kRayShadow] + r.counters.rays[kRayVolume], 0u);
  int inside = 0;
  for (int j = 0; j < 48; ++j)
    for (int i = 0; i < 48; ++i) {
      WorldRay ray = cam.PixelRay(i + 0.5, j + 0.5);
      double len = ChordLength(ray.origin, ray.dir, {4, 4, 4}, {12, 12, 12});
      double expect = std::exp(-0.3 * 0.8 * len);
      inside += len > 0;
      ASSERT_NEAR(r.img.at("R", i, j), expect, 1e-3) << i << "," << j << " length " << len;
      ASSERT_NEAR(r.img.at("A", i, j), 1 - expect, 1e-3);
    }
  EXPECT_GT(inside, 300);
  // With a light, single scattering adds light and traces transmittance rays.
  Rendered lit =
      Render(vol.get(), cam, ParseOrDie(R"({"lights":[{"type":"directional","direction":[0,-1,0]}],
                                       "background":[0,0,0], "volume":{"absorption":0.1,"scattering":0.4}})"));
  EXPECT_TRUE(lit.passes.scattering);
  EXPECT_GT(lit.counters.rays[kRayVolume], 0u);
  EXPECT_GT(lit.img.at("R", 24, 24), 0.05f);
}

TEST(EffectsTest, LevelSetsAreNeverIntegrated) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Sphere({16, 16, 16}, 9)});
  ASSERT_TRUE(vol);
  Camera cam = Persp({16, 16, 60}, {16, 16, 16}, 30, 32, 32);
  Rendered r = Render(vol.get(), cam, ParseOrDie(R"({"volume":{"absorption":5,"scattering":5}})"));
  EXPECT_FALSE(r.passes.volume);
  EXPECT_FALSE(r.passes.scattering);
  EXPECT_EQ(r.counters.rays[kRayVolume], 0u);
  // Alpha is exactly 0 or 1 on surfaces, and 1 exactly where Z is finite.
  for (size_t p = 0; p < r.img.ch["A"].size(); ++p) {
    float a = r.img.ch["A"][p];
    ASSERT_TRUE(a == 0.0f || a == 1.0f);
    EXPECT_EQ(a == 1.0f, std::isfinite(r.img.ch["Z"][p]));
  }
}

TEST(EffectsTest, SplitDoesNotChangeTheImage) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet),
                        {Sphere({15, 17, 16}, 11), Box({2, 2, 2}, {9, 30, 6})});
  ASSERT_TRUE(vol);
  Camera cam = Persp({40, 30, 50}, {16, 16, 16}, 40, 48, 48);
  Scene scene = ParseOrDie(R"({"lights":[{"type":"directional","direction":[-1,-1,-1]}]})");
  Rendered single = Render(vol.get(), cam, scene, 5);
  for (int n1 : {1, 2, 3, 4}) {
    Rendered two = Render(vol.get(), cam, scene, n1);
    EXPECT_EQ(two.img.ch["A"], single.img.ch["A"]) << "n1 " << n1;
    EXPECT_EQ(two.img.ch["Z"], single.img.ch["Z"]) << "n1 " << n1;
    EXPECT_EQ(two.img.ch["R"], single.img.ch["R"]) << "n1 " << n1;
    if (n1 < 5) {
      EXPECT_GT(two.counters.trace.transitions, 0u);
    }
  }
  EXPECT_EQ(single.counters.trace.transitions, 0u);
}

// The bare loop (first_hits_only, vox-render-bench --bare) finds the
// shaded frame's hits: the same coverage, depth and voxels, with no
// attribute read and no secondary ray, whatever the lights ask for.
TEST(EffectsTest, FirstHitsOnlyFindsTheShadedFramesHits) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet),
                        {Sphere({15, 17, 16}, 11), Box({2, 2, 2}, {9, 30, 6})});
  ASSERT_TRUE(vol);
  Camera cam = Persp({40, 30, 50}, {16, 16, 16}, 40, 48, 48);
  Scene scene = ParseOrDie(
      R"({"lights":[{"type":"directional","direction":[-1,-1,-1],"shadows":true}]})");
  ImageLayers layers;
  layers.voxel = true;
  Rendered shaded = Render(vol.get(), cam, scene, 0, layers);
  RenderOptions o;
  o.layers = layers;
  o.first_hits_only = true;
  auto bare = Renderer::Create(vol.get(), cam, scene, o);
  ASSERT_TRUE(bare.ok()) << bare.status().ToString();
  Image img;
  RenderCounters c;
  ASSERT_TRUE(RenderToMemory(**bare, &img, &c).ok());
  EXPECT_GT(shaded.counters.hit_pixels, 500u);
  EXPECT_EQ(c.hit_pixels, shaded.counters.hit_pixels);
  for (const char* ch : {"A", "Z", "voxel.i", "voxel.j", "voxel.k"})
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) {
        const float a = img.at(ch, x, y), b = shaded.img.at(ch, x, y);
        ASSERT_TRUE(a == b || (std::isnan(a) && std::isnan(b))) << ch << " " << x << "," << y;
      }
  EXPECT_GT(shaded.counters.rays[kRayShadow], 0u);
  EXPECT_EQ(c.rays[kRayShadow], 0u);
  EXPECT_EQ(c.attribute_lookups, 0u);
  EXPECT_EQ(c.trace.rays, c.rays[kRayPrimary]);
  EXPECT_EQ(img.at("R", 24, 24), 0.0f);  // no shading
}

TEST(EffectsTest, NormalAndVoxelLayers) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Box({8, 8, 8}, {24, 24, 24})});
  ASSERT_TRUE(vol);
  Camera cam = Ortho({16, 16, 30}, {16, 16, 0}, {0, 1, 0}, 32, 32, 32);
  ImageLayers layers;
  layers.normal = layers.voxel = true;
  Rendered r = Render(vol.get(), cam, ParseOrDie(R"({"lights":[]})"), 0, layers);
  // Pixel (10, 12) sees world (10.5, 19.5) on the top face z = 24: voxel (10, 19, 23).
  EXPECT_EQ(r.img.at("voxel.i", 10, 12), 10.0f);
  EXPECT_EQ(r.img.at("voxel.j", 10, 12), 19.0f);
  EXPECT_EQ(r.img.at("voxel.k", 10, 12), 23.0f);
  EXPECT_NEAR(r.img.at("N.Z", 12, 12), 1.0f, 1e-6);
  EXPECT_EQ(r.img.at("N.X", 0, 0), 0.0f);
  // A miss names no voxel.
  EXPECT_TRUE(std::isnan(r.img.at("voxel.i", 0, 0)));
}

TEST(EffectsTest, SamplesPerPixelGiveFractionalCoverage) {
  auto vol = MakeVolume(TestMeta(5, GridClass::kLevelSet), {Sphere({16, 16, 16}, 9)});
  ASSERT_TRUE(vol);
  Camera cam = Persp({16, 16, 60}, {16, 16, 16}, 30, 32, 32);
  Rendered r = Render(vol.get(), cam, ParseOrDie(R"({"lights":[], "samples_per_pixel":8})"));
  EXPECT_EQ(r.counters.rays[kRayPrimary], 32u * 32u * 8u);
  int partial = 0;
  for (float a : r.img.ch["A"]) partial += a > 0 && a < 1;
  EXPECT_GT(partial, 10);
}

}  // namespace
}  // namespace vox

// The renderer with beam start distances (RenderOptions::beam) against the
// renderer without: every channel of every pixel bit for bit, on perspective
// and orthographic cameras (outside the volume, inside it, inside an occupied
// voxel), several splits and beam block sizes, several samples per pixel,
// lights with shadows and the normal and voxel layers; the beam must save
// walk work; the same for fog; a bad block size is refused.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

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

Camera Cam(Projection p, glm::dvec3 pos, glm::dvec3 at, int w, int h) {
  Camera c;
  c.projection = p;
  c.position = pos;
  c.look_at = at;
  c.fov_deg = 50;
  c.ortho_width = 40;
  c.width = w;
  c.height = h;
  EXPECT_TRUE(c.Finalize().ok());
  return c;
}

struct Out {
  Image img;
  RenderCounters counters;
};

Out Render(Volume* vol, const Camera& cam, const Scene& scene, bool beam, int n1, int block) {
  RenderOptions o;
  o.n1 = n1;
  o.beam = beam;
  o.beam_block = block;
  o.layers.normal = true;
  o.layers.voxel = true;
  auto r = Renderer::Create(vol, cam, scene, o);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  Out out;
  if (!r.ok()) return out;
  Status s = RenderToMemory(**r, &out.img, &out.counters, 24);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return out;
}

// Every channel of every pixel of `a` and `b`, bit for bit.
void ExpectSamePixels(const Image& a, const Image& b, int width, const std::string& what) {
  ASSERT_EQ(a.ch.size(), b.ch.size()) << what;
  for (const auto& [name, px] : a.ch) {
    const std::vector<float>& q = b.ch.at(name);
    ASSERT_EQ(px.size(), q.size()) << what;
    for (size_t i = 0; i < px.size(); ++i)
      ASSERT_EQ(std::memcmp(&px[i], &q[i], sizeof(float)), 0)
          << what << " channel " << name << " pixel " << i % size_t(width) << ","
          << i / size_t(width) << ": " << px[i] << " vs " << q[i];
  }
}

TEST(BeamRender, SamePixelsWithAndWithoutTheBeam) {
  // 64^3 voxels of 0.5 world units: spheres, a thin slab and a lone voxel.
  const StoreMeta meta = TestMeta(6, GridClass::kLevelSet, 0.5);
  auto vol = MakeVolume(meta, {Sphere({12, 14, 16}, 6), Sphere({22, 20, 9}, 3.5),
                               Box({2, 2, 25}, {30, 29, 26.2}), Box({28, 3, 3}, {28.4, 3.4, 3.4})});
  ASSERT_NE(vol, nullptr);
  auto scene = ParseScene(
      R"({"lights": [{"type": "point", "position": [40, 40, 40], "intensity": 1, "shadows": true}],
          "samples_per_pixel": 3})",
      "scene");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const std::vector<Camera> cams = {
      Cam(Projection::kPerspective, {60, 45, 70}, {16, 16, 16}, 61, 47),
      Cam(Projection::kPerspective, {16, 16, -30}, {16, 16, 16}, 48, 48),  // axis-parallel centre
      Cam(Projection::kPerspective, {20, 8, 20}, {5, 20, 10}, 40, 33),     // inside the volume
      Cam(Projection::kPerspective, {12, 14, 16}, {30, 14, 16}, 32, 32),   // inside a sphere
      Cam(Projection::kOrthographic, {16, 16, 60}, {16, 16, 0}, 50, 40),
      Cam(Projection::kOrthographic, {50, -20, 45}, {16, 16, 16}, 37, 52)};
  uint64_t cells_on = 0, cells_off = 0;
  int k = 0;
  for (const Camera& cam : cams)
    for (int n1 : {0, 2, 6})
      for (int block : {8, 3}) {
        const Out off = Render(vol.get(), cam, *scene, false, n1, block);
        const Out on = Render(vol.get(), cam, *scene, true, n1, block);
        const std::string what = "camera " + std::to_string(k) + " n1 " + std::to_string(n1) +
                                 " block " + std::to_string(block);
        ASSERT_NO_FATAL_FAILURE(ExpectSamePixels(off.img, on.img, cam.width, what));
        EXPECT_EQ(off.counters.hit_pixels, on.counters.hit_pixels) << what;
        EXPECT_GT(on.counters.hit_pixels, on.counters.pixels / 20) << what;
        EXPECT_EQ(off.counters.trace.hits, on.counters.trace.hits) << what;
        // Rays of blocks whose beam meets nothing skip the walk, not the count.
        EXPECT_EQ(off.counters.trace.rays, on.counters.trace.rays) << what;
        EXPECT_EQ(off.counters.rays[kRayPrimary], on.counters.rays[kRayPrimary]) << what;
        EXPECT_EQ(on.counters.rays[kRayPrimary], on.counters.pixels * 3) << what;
        cells_on += on.counters.trace.cells_visited;
        cells_off += off.counters.trace.cells_visited;
        ++k;
      }
  EXPECT_LT(cells_on, cells_off);
}

TEST(BeamRender, FogSamePixelsWithAndWithoutTheBeam) {
  // A fog of two spheres of different densities, lit with shadows: a fog
  // ray starts its walk at its block's plane, and the integral is the same.
  const StoreMeta meta = TestMeta(6, GridClass::kFogVolume, 0.5);
  Part a = Sphere({10, 12, 14}, 6), b = Sphere({22, 20, 12}, 4);
  a.density = 0.7f;
  b.density = 2.5f;
  auto vol = MakeVolume(meta, {a, b});
  ASSERT_NE(vol, nullptr);
  auto scene = ParseScene(
      R"({"lights": [{"type": "directional", "direction": [-1, -2, -1], "intensity": 1,
                      "shadows": true}], "samples_per_pixel": 2})",
      "scene");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const std::vector<Camera> cams = {
      Cam(Projection::kPerspective, {36, 30, 40}, {16, 16, 14}, 53, 41),
      Cam(Projection::kPerspective, {10, 12, 14}, {30, 14, 16}, 32, 32),  // inside the fog
      Cam(Projection::kOrthographic, {16, 16, 60}, {16, 16, 0}, 40, 36)};
  uint64_t cells_on = 0, cells_off = 0;
  for (size_t k = 0; k < cams.size(); ++k) {
    const Out off = Render(vol.get(), cams[k], *scene, false, 3, 8);
    const Out on = Render(vol.get(), cams[k], *scene, true, 3, 8);
    ASSERT_NO_FATAL_FAILURE(
        ExpectSamePixels(off.img, on.img, cams[k].width, "camera " + std::to_string(k)));
    EXPECT_GT(on.counters.hit_pixels, on.counters.pixels / 20) << "camera " << k;
    cells_on += on.counters.trace.cells_visited;
    cells_off += off.counters.trace.cells_visited;
  }
  EXPECT_LT(cells_on, cells_off);
}

TEST(BeamRender, RefusesABadBlockSize) {
  const StoreMeta meta = TestMeta(5, GridClass::kLevelSet);
  auto vol = MakeVolume(meta, {Sphere({16, 16, 16}, 5)});
  ASSERT_NE(vol, nullptr);
  RenderOptions o;
  o.beam_block = 0;
  auto r = Renderer::Create(
      vol.get(), Cam(Projection::kPerspective, {16, 16, 50}, {16, 16, 16}, 8, 8), Scene(), o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("beam block 0"), std::string::npos) << r.status().ToString();
  o.beam = false;  // ignored when the beam is off
  EXPECT_TRUE(Renderer::Create(vol.get(),
                               Cam(Projection::kPerspective, {16, 16, 50}, {16, 16, 16}, 8, 8),
                               Scene(), o)
                  .ok());
}

}  // namespace
}  // namespace vox

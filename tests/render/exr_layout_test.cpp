// The EXR layout compositors expect (render/exr.h, docs/usage.md): colour
// premultiplied by alpha with misses 0, 0, 0, 0 (fog too: no background),
// the background only with the scene's "background_in_exr"; Z the planar
// camera depth, the ray distance in the `distance` layer; N.X N.Y N.Z, a
// world-position layer P.X P.Y P.Z, misses marked NaN in the voxel layer;
// the PNG preview composed over the background; vox-merge keeps every layer.
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <glm/geometric.hpp>

#include "render/camera.h"
#include "render/exr.h"
#include "render/job.h"
#include "render/merge.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

// Off-centre and wide, so the corners' rays are far from the view axis.
const char kCam[] =
    R"({"position":[2,3,14], "look_at":[0.5,0,0], "fov_deg":60, "width":64, "height":48})";

class ExrLayoutTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_exr_layout_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    ASSERT_TRUE(testing::WriteSphereShellStore(Path("sphere")).ok());
    // A fog cube of density 0.6: world [4,12)^3.
    StoreMeta meta = testing::TestMeta(5, GridClass::kFogVolume, 0.5);
    meta.brick_level = 2;
    std::vector<MemoryVoxel> voxels;
    for (int z = 8; z < 24; ++z)
      for (int y = 8; y < 24; ++y)
        for (int x = 8; x < 24; ++x) {
          MemoryVoxel v;
          v.x = uint64_t(x), v.y = uint64_t(y), v.z = uint64_t(z);
          v.attr.density = 0.6f;
          voxels.push_back(v);
        }
    ASSERT_TRUE(testing::WriteStore(Path("fog"), meta, voxels).ok());
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }

  // Renders `store` with every layer, float colour, to `name`.exr.
  static ExrImage Render(const std::string& store, const std::string& cam,
                         const std::string& scene, const std::string& name,
                         const std::string& preview = "", PartSpec part = {}) {
    RenderJobOptions o;
    o.store_dir = Path(store);
    o.camera_json = cam;
    o.scene_json = scene;
    o.exr_path = Path(name + ".exr");
    o.preview_path = preview.empty() ? "" : Path(preview);
    o.quiet = true;
    o.threads = 2;
    o.tile_size = 16;
    o.part = part;
    o.layers.normal = o.layers.voxel = o.layers.position = o.layers.distance = true;
    o.layers.float_color = true;
    Status s = RunRenderJob(o);
    EXPECT_TRUE(s.ok()) << s.ToString();
    if (!part.whole()) return ExrImage();
    auto img = ReadExr(o.exr_path);
    EXPECT_TRUE(img.ok()) << img.status().ToString();
    return img.ok() ? *img : ExrImage();
  }

  static fs::path* dir_;
};
fs::path* ExrLayoutTest::dir_ = nullptr;

bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST_F(ExrLayoutTest, ChannelNames) {
  const ExrImage img = Render("sphere", kCam, "{}", "names");
  std::vector<std::string> want = {"A",   "B",   "G",   "N.X",      "N.Y",     "N.Z",
                                   "P.X", "P.Y", "P.Z", "R",        "Z",       "distance",
                                   "voxel.i", "voxel.j", "voxel.k"};
  std::vector<std::string> got = img.info.channels;
  std::sort(want.begin(), want.end());
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, want);
}

TEST_F(ExrLayoutTest, MissesAreZeroAndTheBackgroundOnlyOnRequest) {
  const char kScene[] = R"({"background":[0.3,0.4,0.5]})";
  const char kOpaque[] = R"({"background":[0.3,0.4,0.5], "background_in_exr":true})";
  ExrImage pre = Render("sphere", kCam, kScene, "pre");
  ExrImage opaque = Render("sphere", kCam, kOpaque, "opaque");
  int misses = 0, hits = 0;
  for (size_t p = 0; p < pre.pixels["A"].size(); ++p) {
    const float a = pre.pixels["A"][p];
    ASSERT_TRUE(a == 0.0f || a == 1.0f);
    ASSERT_EQ(a, opaque.pixels["A"][p]);
    for (const char* c : {"Z", "N.X", "voxel.i", "P.Y", "distance"})
      ASSERT_TRUE(SameBits(pre.pixels[c][p], opaque.pixels[c][p])) << c << " at " << p;
    if (a == 0.0f) {
      ++misses;
      for (const char* c : {"R", "G", "B"}) ASSERT_EQ(pre.pixels[c][p], 0.0f) << c << " at " << p;
      EXPECT_EQ(opaque.pixels["R"][p], 0.3f);
      EXPECT_EQ(opaque.pixels["B"][p], 0.5f);
      EXPECT_TRUE(std::isinf(pre.pixels["Z"][p]));
      EXPECT_TRUE(std::isinf(pre.pixels["distance"][p]));
      for (const char* c : {"voxel.i", "voxel.j", "voxel.k"})
        EXPECT_TRUE(std::isnan(pre.pixels[c][p])) << c << " at " << p;
      for (const char* c : {"P.X", "P.Y", "P.Z", "N.X"}) EXPECT_EQ(pre.pixels[c][p], 0.0f);
    } else {
      ++hits;  // a hit is opaque: the same colour either way
      for (const char* c : {"R", "G", "B"})
        ASSERT_TRUE(SameBits(pre.pixels[c][p], opaque.pixels[c][p])) << c << " at " << p;
      EXPECT_FALSE(std::isnan(pre.pixels["voxel.i"][p]));
    }
  }
  EXPECT_GT(misses, 300);
  EXPECT_GT(hits, 300);
}

TEST_F(ExrLayoutTest, ZIsPlanarDepthAndDistanceIsAlongTheRay) {
  ExrImage img = Render("sphere", kCam, "{}", "depth");
  auto cam = ParseCamera(kCam, "cam");
  ASSERT_TRUE(cam.ok());
  const glm::dvec3 f = glm::normalize(cam->look_at - cam->position);
  int checked = 0;
  double largest_gap = 0;
  for (int j = 0; j < img.info.height; ++j)
    for (int i = 0; i < img.info.width; ++i) {
      const size_t p = size_t(j) * img.info.width + i;
      if (img.pixels["A"][p] != 1.0f) continue;
      const WorldRay ray = cam->PixelRay(i + 0.5, j + 0.5);
      const double dist = img.pixels["distance"][p], z = img.pixels["Z"][p];
      const glm::dvec3 hit = ray.origin + dist * ray.dir;
      const glm::dvec3 pos(img.pixels["P.X"][p], img.pixels["P.Y"][p], img.pixels["P.Z"][p]);
      ASSERT_NEAR(glm::length(pos - hit), 0.0, 1e-5 * dist) << i << "," << j;
      // The shell: world radius 4.25..5, within a voxel (0.25).
      ASSERT_GT(glm::length(pos), 4.0);
      ASSERT_LT(glm::length(pos), 5.3);
      // Planar: the hit's distance along the view axis.
      ASSERT_NEAR(z, glm::dot(hit - cam->position, f), 1e-5 * dist) << i << "," << j;
      largest_gap = std::max(largest_gap, dist - z);
      ++checked;
    }
  EXPECT_GT(checked, 300);
  EXPECT_GT(largest_gap, 0.3);  // off-axis pixels: planar depth is clearly shorter
}

TEST_F(ExrLayoutTest, FogIsPremultipliedWithoutBackground) {
  const char kCamFog[] =
      R"({"position":[9,10.5,25], "look_at":[8,8,8], "fov_deg":40, "width":40, "height":40})";
  const char kLit[] = R"({"lights":[{"type":"directional","direction":[0,-1,0]}],
      "background":[0.5,0.25,1], "volume":{"absorption":0.1,"scattering":0.4}})";
  const char kLitOpaque[] = R"({"lights":[{"type":"directional","direction":[0,-1,0]}],
      "background":[0.5,0.25,1], "background_in_exr":true,
      "volume":{"absorption":0.1,"scattering":0.4}})";
  ExrImage pre = Render("fog", kCamFog, kLit, "fog_pre");
  ExrImage opaque = Render("fog", kCamFog, kLitOpaque, "fog_opaque");
  int partial = 0;
  for (size_t p = 0; p < pre.pixels["A"].size(); ++p) {
    const float a = pre.pixels["A"][p];
    ASSERT_EQ(a, opaque.pixels["A"][p]);
    const float bg[3] = {0.5f, 0.25f, 1.0f};
    const char* names[3] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c) {
      // L, and L + (1 - A) background.
      ASSERT_NEAR(opaque.pixels[names[c]][p], pre.pixels[names[c]][p] + (1 - a) * bg[c], 1e-5);
      ASSERT_LE(pre.pixels[names[c]][p], a * 1.0f + 1e-6);  // no light beyond its coverage here
    }
    if (a == 0.0f) {
      ASSERT_EQ(pre.pixels["R"][p], 0.0f);
    }
    partial += a > 0.05f && a < 0.95f;
    if (a > 0) {
      EXPECT_TRUE(std::isnan(pre.pixels["voxel.i"][p]));  // fog names no single voxel
      EXPECT_TRUE(std::isfinite(pre.pixels["Z"][p]));
    }
  }
  EXPECT_GT(partial, 100);
}

std::vector<uint8_t> ReadPng(const std::string& path) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str())) return {};
  image.format = PNG_FORMAT_RGB;
  std::vector<uint8_t> px(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, px.data(), 0, nullptr)) return {};
  return px;
}

TEST_F(ExrLayoutTest, PreviewShowsTheBackgroundEitherWay) {
  const char kScene[] = R"({"background":{"top":[0.9,0.2,0.1],"bottom":[0.1,0.2,0.9]}})";
  const char kOpaque[] =
      R"({"background":{"top":[0.9,0.2,0.1],"bottom":[0.1,0.2,0.9]}, "background_in_exr":true})";
  Render("sphere", kCam, kScene, "pv_pre", "pv_pre.png");
  Render("sphere", kCam, kOpaque, "pv_opaque", "pv_opaque.png");
  const std::vector<uint8_t> a = ReadPng(Path("pv_pre.png")), b = ReadPng(Path("pv_opaque.png"));
  ASSERT_EQ(a.size(), size_t(64 * 48 * 3));
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) ASSERT_NEAR(int(a[k]), int(b[k]), 1) << k;
  // The top-left corner is a miss: the sky, not black.
  EXPECT_GT(a[0], 100);
}

TEST_F(ExrLayoutTest, MergedPartsKeepEveryLayerBitForBit) {
  ExrImage whole = Render("sphere", kCam, "{}", "whole");
  Render("sphere", kCam, "{}", "part1", "", PartSpec{1, 3});
  Render("sphere", kCam, "{}", "part2", "", PartSpec{2, 3});
  Render("sphere", kCam, "{}", "part3", "", PartSpec{3, 3});
  ASSERT_TRUE(MergeParts({Path("part1.exr"), Path("part2.exr"), Path("part3.exr")},
                         Path("merged.exr"), nullptr)
                  .ok());
  auto merged = ReadExr(Path("merged.exr"));
  ASSERT_TRUE(merged.ok()) << merged.status().ToString();
  EXPECT_EQ(merged->info.channels, whole.info.channels);
  for (const auto& [name, px] : whole.pixels) {
    const auto& m = merged->pixels.at(name);
    ASSERT_EQ(m.size(), px.size());
    EXPECT_EQ(std::memcmp(m.data(), px.data(), px.size() * sizeof(float)), 0) << name;
  }
}

}  // namespace
}  // namespace vox

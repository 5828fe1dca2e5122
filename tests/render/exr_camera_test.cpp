// The standard camera attributes of vox-render's EXRs (render/exr.h):
// every hit pixel's 3D point, rebuilt from its Z and the camera, projects
// through the header's worldToNDC onto that pixel's centre, for perspective
// and orthographic cameras; worldToCamera puts the point at depth > 0 along
// the view; the screen window matches the camera; vox-merge keeps them all.
// The EXRs are read back with OpenEXR itself, the rays rebuilt here from the
// cam.json conventions (render/camera.h), not with vox's Camera.
#include <gtest/gtest.h>
#include <unistd.h>

#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <glm/geometric.hpp>

#include "render/job.h"
#include "render/merge.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

struct Exr {
  int width = 0, height = 0;
  Imath::M44f world_to_ndc, world_to_camera;
  Imath::V2f screen_center;
  float screen_width = 0;
  bool has_matrices = false;
  std::vector<float> a, z;
};

Exr ReadBack(const std::string& path) {
  Imf::InputFile in(path.c_str());
  const Imf::Header& h = in.header();
  Exr e;
  const auto dw = h.dataWindow();
  e.width = dw.max.x - dw.min.x + 1;
  e.height = dw.max.y - dw.min.y + 1;
  e.has_matrices = Imf::hasWorldToNDC(h) && Imf::hasWorldToCamera(h);
  if (e.has_matrices) {
    e.world_to_ndc = Imf::worldToNDC(h);
    e.world_to_camera = Imf::worldToCamera(h);
  }
  e.screen_center = h.screenWindowCenter();
  e.screen_width = h.screenWindowWidth();
  e.a.resize(size_t(e.width) * e.height);
  e.z.resize(e.a.size());
  Imf::FrameBuffer fb;
  fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(e.a.data()), 4, 4 * e.width));
  fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(e.z.data()), 4, 4 * e.width));
  in.setFrameBuffer(fb);
  in.readPixels(dw.min.y, dw.max.y);
  return e;
}

struct Cam {
  glm::dvec3 pos, look, up{0, 1, 0};
  bool perspective = true;
  double fov_deg = 40, ortho_width = 0;
  int width = 0, height = 0;
  std::string Json() const {
    char b[512];
    if (perspective)
      snprintf(b, sizeof b,
               R"({"position":[%.17g,%.17g,%.17g],"look_at":[%.17g,%.17g,%.17g],"up":[0,1,0],)"
               R"("fov_deg":%.17g,"width":%d,"height":%d,"projection":"perspective"})",
               pos.x, pos.y, pos.z, look.x, look.y, look.z, fov_deg, width, height);
    else
      snprintf(b, sizeof b,
               R"({"position":[%.17g,%.17g,%.17g],"look_at":[%.17g,%.17g,%.17g],"up":[0,1,0],)"
               R"("ortho_width":%.17g,"width":%d,"height":%d,"projection":"orthographic"})",
               pos.x, pos.y, pos.z, look.x, look.y, look.z, ortho_width, width, height);
    return b;
  }
  // cam.json's documented mapping: pixel (x, y) -> screen ((2x/W - 1) s,
  // (1 - 2y/H) s H/W), s = tan(fov/2) or ortho_width/2.
  void Ray(double x, double y, glm::dvec3* o, glm::dvec3* d) const {
    const glm::dvec3 f = glm::normalize(look - pos);
    const glm::dvec3 r = glm::normalize(glm::cross(f, up));
    const glm::dvec3 u = glm::cross(r, f);
    const double s = perspective ? std::tan(fov_deg * M_PI / 360.0) : ortho_width / 2;
    const double sx = (2 * x / width - 1) * s, sy = (1 - 2 * y / height) * s * height / width;
    if (perspective) {
      *o = pos;
      *d = glm::normalize(f + sx * r + sy * u);
    } else {
      *o = pos + sx * r + sy * u;
      *d = f;
    }
  }
};

class ExrCameraTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vox_exr_camera_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
    ASSERT_TRUE(testing::WriteSphereShellStore(Path("store")).ok());
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& n) const { return (dir_ / n).string(); }

  std::string Render(const Cam& cam, const std::string& name, PartSpec part = {}) {
    std::ofstream(Path(name + ".json")) << cam.Json();
    RenderJobOptions o;
    o.store_dir = Path("store");
    o.camera_path = Path(name + ".json");
    o.exr_path = Path(name + ".exr");
    o.quiet = true;
    o.threads = 2;
    o.tile_size = 16;
    o.part = part;
    Status s = RunRenderJob(o);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return o.exr_path;
  }

  // Projects every hit pixel's point; returns the number checked.
  int CheckProjection(const Cam& cam, const Exr& e) {
    EXPECT_TRUE(e.has_matrices);
    EXPECT_EQ(e.width, cam.width);
    int checked = 0;
    double worst = 0;
    for (int j = 0; j < e.height; ++j)
      for (int i = 0; i < e.width; ++i) {
        const float z = e.z[size_t(j) * e.width + i];
        if (!(e.a[size_t(j) * e.width + i] > 0) || !std::isfinite(z)) continue;
        glm::dvec3 o, d;
        cam.Ray(i + 0.5, j + 0.5, &o, &d);
        // Z is planar depth: the ray reaches it at z / cos(angle to the view axis).
        const glm::dvec3 p = o + double(z) / glm::dot(d, glm::normalize(cam.look - cam.pos)) * d;
        const Imath::M44f& m = e.world_to_ndc;
        double v[4];
        for (int c = 0; c < 4; ++c) v[c] = p.x * m[0][c] + p.y * m[1][c] + p.z * m[2][c] + m[3][c];
        const double px = v[0] / v[3] * cam.width, py = v[1] / v[3] * cam.height;
        worst = std::max({worst, std::abs(px - (i + 0.5)), std::abs(py - (j + 0.5))});
        // In front of the camera, at the depth the ray reached.
        const Imath::M44f& c = e.world_to_camera;
        const double depth = p.x * c[0][2] + p.y * c[1][2] + p.z * c[2][2] + c[3][2];
        const double along = glm::dot(p - cam.pos, glm::normalize(cam.look - cam.pos));
        EXPECT_NEAR(depth, along, 1e-4 * std::max(1.0, along));
        ++checked;
      }
    EXPECT_LT(worst, 1e-3) << "worst pixel offset " << worst;
    return checked;
  }

  fs::path dir_;
};

TEST_F(ExrCameraTest, PerspectiveHitsProjectOntoTheirPixelCentres) {
  Cam cam;
  cam.pos = {3, 4, 17};
  cam.look = {0.5, -0.25, 0};
  cam.fov_deg = 38;
  cam.width = 96;
  cam.height = 72;
  const Exr e = ReadBack(Render(cam, "persp"));
  EXPECT_GT(CheckProjection(cam, e), 1000);
  EXPECT_EQ(e.screen_center, Imath::V2f(0, 0));
  EXPECT_NEAR(e.screen_width, 2 * std::tan(38 * M_PI / 360), 1e-6);
}

TEST_F(ExrCameraTest, OrthographicHitsProjectOntoTheirPixelCentres) {
  Cam cam;
  cam.perspective = false;
  cam.pos = {-9, 6, 12};
  cam.look = {0, 0.5, 0};
  cam.ortho_width = 13;
  cam.width = 80;
  cam.height = 100;
  const Exr e = ReadBack(Render(cam, "ortho"));
  EXPECT_GT(CheckProjection(cam, e), 1000);
  EXPECT_EQ(e.screen_center, Imath::V2f(0, 0));
  EXPECT_NEAR(e.screen_width, 13.0, 1e-6);
}

TEST_F(ExrCameraTest, MergeKeepsTheStandardAttributes) {
  Cam cam;
  cam.pos = {0, 3, 20};
  cam.look = {0, 0, 0};
  cam.width = 64;
  cam.height = 48;
  const Exr whole = ReadBack(Render(cam, "whole"));
  const std::string p1 = Render(cam, "p1", {1, 2}), p2 = Render(cam, "p2", {2, 2});
  ASSERT_TRUE(MergeParts({p1, p2}, Path("merged.exr"), nullptr).ok());
  const Exr merged = ReadBack(Path("merged.exr"));
  ASSERT_TRUE(merged.has_matrices);
  EXPECT_EQ(merged.world_to_ndc, whole.world_to_ndc);
  EXPECT_EQ(merged.world_to_camera, whole.world_to_camera);
  EXPECT_EQ(merged.screen_width, whole.screen_width);
  EXPECT_EQ(merged.z, whole.z);
  EXPECT_GT(CheckProjection(cam, merged), 100);
}

}  // namespace
}  // namespace vox

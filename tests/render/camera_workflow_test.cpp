// The camera workflow (docs/usage.md): --size overrides the camera JSON and
// --stats says what was used; --view frames the volume's world box from an
// azimuth and elevation; --save-cam writes a camera that renders the same
// image again; camera_to_world (Blender/OpenGL: -Z ahead, +Y up) renders the
// same image as the equivalent look_at camera, bit for bit; fov_axis.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "render/camera.h"
#include "render/exr.h"
#include "render/grid_transform.h"
#include "render/job.h"
#include "core/util/file.h"
#include "tests/render/store_suite.h"
#include "tests/render/store_util.h"
#include "tools/common/options.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

const char kCam[] =
    R"({"position":[3,4,17], "look_at":[0.5,-0.25,0], "up":[0,1,0], "fov_deg":38, "width":64, "height":48})";

class CameraWorkflowTest : public testing::SphereShellStoreSuite {
 protected:
  struct Run {
    Status status;
    RenderJobOutput out;
    nlohmann::json stats;
  };
  // Renders the store with vox-render's flags (as the tool and Python apply them).
  static Run Render(const std::vector<std::pair<std::string, std::string>>& flags) {
    RenderJobOptions o;
    o.store_dir = Path("store");
    o.exr_path.clear();
    o.quiet = true;
    o.threads = 2;
    o.tile_size = 16;
    o.keep_image = true;
    Run r;
    for (const auto& [f, v] : flags) {
      r.status = ApplyRenderFlag(&o, f, v);
      if (!r.status.ok()) return r;
    }
    r.status = RunRenderJob(o, &r.out);
    if (r.status.ok()) r.stats = nlohmann::json::parse(r.out.stats_json);
    return r;
  }
  static bool SameImage(const RenderJobOutput& a, const RenderJobOutput& b) {
    return a.width == b.width && a.height == b.height && a.rgba.size() == b.rgba.size() &&
           std::memcmp(a.rgba.data(), b.rgba.data(), a.rgba.size() * 4) == 0 &&
           std::memcmp(a.z.data(), b.z.data(), a.z.size() * 4) == 0;
  }
  static int Hits(const RenderJobOutput& a) {
    int n = 0;
    for (size_t p = 0; p < a.z.size(); ++p) n += a.rgba[p * 4 + 3] > 0;
    return n;
  }

};

TEST_F(CameraWorkflowTest, SizeOverridesTheCameraJsonAndStatsSaySo) {
  const std::string cam = Write("cam.json", kCam);
  Run json_size = Render({{"--cam", cam}});
  ASSERT_TRUE(json_size.status.ok()) << json_size.status.ToString();
  EXPECT_EQ(json_size.out.width, 64);
  EXPECT_EQ(json_size.stats["camera"]["source"]["size"], "camera");
  Run r = Render({{"--cam", cam}, {"--size", "40x30"}});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.out.width, 40);
  EXPECT_EQ(r.out.height, 30);
  EXPECT_EQ(r.stats["image"]["width"], 40);
  EXPECT_EQ(r.stats["camera"]["width"], 40);
  EXPECT_EQ(r.stats["camera"]["height"], 30);
  EXPECT_EQ(r.stats["camera"]["source"]["size"], "--size");
  EXPECT_EQ(r.stats["camera"]["source"]["camera"], cam);
  EXPECT_EQ(r.stats["camera"]["fov_deg"], 38.0);
  // The camera JSON as text (the Python module's dicts) too.
  RenderJobOptions o;
  ASSERT_TRUE(ApplyRenderFlag(&o, "--size", "20x10").ok());
  o.store_dir = Path("store");
  o.exr_path.clear();
  o.quiet = true;
  o.keep_image = true;
  o.camera_json = kCam;
  RenderJobOutput out;
  ASSERT_TRUE(RunRenderJob(o, &out).ok());
  EXPECT_EQ(out.width, 20);
  EXPECT_EQ(out.height, 10);
}

TEST_F(CameraWorkflowTest, ViewFramesTheWorldBoxAndSaveCamRendersTheSameImage) {
  Run r = Render({{"--view", "30,20"}, {"--size", "64x48"}, {"--save-cam", Path("used.json")}});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_GT(Hits(r.out), 300);
  auto used = LoadCamera(Path("used.json"));
  ASSERT_TRUE(used.ok()) << used.status().ToString();
  EXPECT_EQ(r.stats["camera"]["source"]["view"], nlohmann::json({30.0, 20.0}));
  // Around the box's centre: azimuth 30 from +Z towards +X, elevation 20 up +Y.
  auto store = Store::Open(Path("store"), OpenOptions());
  ASSERT_TRUE(store.ok());
  glm::dvec3 lo, hi;
  WorldBounds((*store)->meta(), &lo, &hi);
  const glm::dvec3 centre = 0.5 * (lo + hi);
  EXPECT_NEAR(glm::length(used->look_at - centre), 0.0, 1e-9);
  const glm::dvec3 w = glm::normalize(used->position - centre);
  const double az = 30 * M_PI / 180, el = 20 * M_PI / 180;
  EXPECT_NEAR(w.x, std::cos(el) * std::sin(az), 1e-9);
  EXPECT_NEAR(w.y, std::sin(el), 1e-9);
  EXPECT_NEAR(w.z, std::cos(el) * std::cos(az), 1e-9);
  // Every corner of the box is in the image, and one is close to its border.
  double fill = 0;
  for (int k = 0; k < 8; ++k) {
    const glm::dvec3 c(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
    const glm::dvec3 d = c - used->position;
    const double z = glm::dot(d, used->forward());
    const double sx = glm::dot(d, used->right()) / z / used->scale_x();
    const double sy = glm::dot(d, used->true_up()) / z / used->scale_y();
    ASSERT_LE(std::abs(sx), 1.0);
    ASSERT_LE(std::abs(sy), 1.0);
    fill = std::max({fill, std::abs(sx), std::abs(sy)});
  }
  EXPECT_GT(fill, 0.95);
  // The saved camera renders the same image, bit for bit.
  Run again = Render({{"--cam", Path("used.json")}});
  ASSERT_TRUE(again.status.ok()) << again.status.ToString();
  EXPECT_TRUE(SameImage(r.out, again.out));
  // --view with --cam keeps its lens and size.
  Run lens = Render({{"--cam", Write("narrow.json", kCam)}, {"--view", "-45,10"}});
  ASSERT_TRUE(lens.status.ok()) << lens.status.ToString();
  EXPECT_EQ(lens.out.width, 64);
  EXPECT_EQ(lens.stats["camera"]["fov_deg"], 38.0);
  // Orthographic: ortho_width frames the box.
  Run ortho = Render({{"--cam", Write("ortho.json",
                                      R"({"position":[0,0,20], "look_at":[0,0,0], "width":40,
                                          "height":40, "projection":"orthographic",
                                          "ortho_width":1})")},
                      {"--view", "0,0"}});
  ASSERT_TRUE(ortho.status.ok()) << ortho.status.ToString();
  EXPECT_NEAR(ortho.stats["camera"]["ortho_width"].get<double>(), (hi.x - lo.x) / 0.98, 1e-6);
  EXPECT_GT(Hits(ortho.out), 400);
  EXPECT_FALSE(Render({{"--view", "10,90"}}).status.ok());
  EXPECT_FALSE(Render({{"--view", "10"}}).status.ok());
}

// cam.json text with camera_to_world: the frame of `c` as columns (x right,
// y up, z back), its position as the last column; row-major.
std::string MatrixJson(const Camera& c) {
  const glm::dvec3 x = c.right(), y = c.true_up(), z = -c.forward(), p = c.position;
  char b[1024];
  snprintf(b, sizeof b,
           R"({"camera_to_world":[[%.17g,%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g,%.17g],)"
           R"([%.17g,%.17g,%.17g,%.17g],[0,0,0,1]], "fov_deg":%.17g, "width":%d, "height":%d})",
           x.x, y.x, z.x, p.x, x.y, y.y, z.y, p.y, x.z, y.z, z.z, p.z, c.fov_deg, c.width,
           c.height);
  return b;
}

TEST_F(CameraWorkflowTest, CameraToWorldRendersTheLookAtImageBitForBit) {
  auto look = ParseCamera(kCam, "cam");
  ASSERT_TRUE(look.ok());
  const std::string matrix = Write("matrix.json", MatrixJson(*look));
  Run a = Render({{"--cam", Write("look.json", kCam)}});
  Run b = Render({{"--cam", matrix}, {"--save-cam", Path("matrix_used.json")}});
  ASSERT_TRUE(a.status.ok()) << a.status.ToString();
  ASSERT_TRUE(b.status.ok()) << b.status.ToString();
  EXPECT_GT(Hits(a.out), 300);
  EXPECT_TRUE(SameImage(a.out, b.out));
  // The saved matrix camera again.
  Run c = Render({{"--cam", Path("matrix_used.json")}});
  ASSERT_TRUE(c.status.ok()) << c.status.ToString();
  EXPECT_TRUE(SameImage(a.out, c.out));
  // Written by hand: Blender's camera at (0, 0, 20) with no rotation looks
  // down -Z with +Y up, as look_at (0, 0, 0) does.
  Run hand = Render({{"--cam", Write("hand.json", R"({"camera_to_world":[1,0,0,0, 0,1,0,0,
      0,0,1,20, 0,0,0,1], "fov_deg":40, "width":48, "height":48})")}});
  Run hand_look = Render({{"--cam", Write("hand_look.json", R"({"position":[0,0,20],
      "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40, "width":48, "height":48})")}});
  ASSERT_TRUE(hand.status.ok()) << hand.status.ToString();
  ASSERT_TRUE(hand_look.status.ok());
  EXPECT_TRUE(SameImage(hand.out, hand_look.out));
  // A camera turned 90 degrees about +Y looks down -X: from (20, 0, 0) at the origin.
  auto turned = ParseCamera(R"({"camera_to_world":[0,0,1,20, 0,1,0,0, -1,0,0,0, 0,0,0,1],
      "fov_deg":40, "width":8, "height":8})", "turned");
  ASSERT_TRUE(turned.ok()) << turned.status().ToString();
  EXPECT_EQ(turned->forward(), glm::dvec3(-1, 0, 0));
  EXPECT_EQ(turned->position, glm::dvec3(20, 0, 0));
}

TEST_F(CameraWorkflowTest, CameraJsonRefusals) {
  auto refuse = [](const std::string& json, const std::string& field) {
    auto c = ParseCamera(json, "c.json");
    ASSERT_FALSE(c.ok()) << json;
    EXPECT_NE(c.status().message().find(field), std::string::npos) << c.status().ToString();
  };
  const std::string rest = R"("fov_deg":40, "width":8, "height":8})";
  refuse(R"({"camera_to_world":[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "position":[0,0,1], )" + rest,
         "position");
  refuse(R"({"camera_to_world":[1,0,0,0, 0,1,0,0, 0,0,1,0], )" + rest, "camera_to_world");
  refuse(R"({"camera_to_world":[1,0.5,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], )" + rest, "orthogonal");
  refuse(R"({"camera_to_world":[-1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], )" + rest, "mirrors");
  // A rotation scaled by 1e200: its axes' lengths overflow, which is said
  // (not "mirrors", which it does not).
  {
    auto c = ParseCamera(R"({"camera_to_world":[1e200,0,0,0, 0,1e200,0,0, 0,0,1e200,0, 0,0,0,1], )" +
                             rest, "c.json");
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.status().message().find(
                  "field 'camera_to_world' has an axis too long to normalise (its length "
                  "overflows)"),
              std::string::npos) << c.status().ToString();
    EXPECT_EQ(c.status().message().find("mirrors"), std::string::npos) << c.status().ToString();
  }
  // Scaled within range, it is the rotation.
  EXPECT_TRUE(ParseCamera(R"({"camera_to_world":[1e100,0,0,0, 0,1e100,0,0, 0,0,1e100,0, 0,0,0,1], )" +
                              rest, "c.json").ok());
  refuse(R"({"camera_to_world":[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,1,1], )" + rest, "last row");
  refuse(R"({"position":[0,0,1], "look_at":[0,0,0], "fov_axis":"z", )" + rest, "fov_axis");
  refuse(R"({"position":[0,0,1], "look_at":[0,0,0], "projection":"orthographic", "ortho_width":2,
      "fov_axis":"y", "width":8, "height":8})",
         "fov_axis");
  // A scaled rotation is normalised.
  auto scaled = ParseCamera(R"({"camera_to_world":[2,0,0,0, 0,2,0,0, 0,0,2,5, 0,0,0,1], )" + rest,
                            "scaled");
  ASSERT_TRUE(scaled.ok()) << scaled.status().ToString();
  EXPECT_EQ(scaled->forward(), glm::dvec3(0, 0, -1));
}

TEST_F(CameraWorkflowTest, FovAxis) {
  const std::string base = R"({"position":[0,0,20], "look_at":[0,0,0], "fov_deg":30, )";
  auto x = ParseCamera(base + R"("width":64, "height":32})", "x");
  auto y = ParseCamera(base + R"("fov_axis":"y", "width":64, "height":32})", "y");
  ASSERT_TRUE(x.ok() && y.ok());
  const double t = std::tan(30 * M_PI / 360);
  EXPECT_EQ(x->scale_x(), t);
  EXPECT_EQ(y->scale_y(), t);  // the vertical half-extent is tan(fov/2)
  EXPECT_DOUBLE_EQ(y->scale_x(), 2 * t);
  EXPECT_NEAR(y->HorizontalFovDeg(), 2 * std::atan(2 * t) * 180 / M_PI, 1e-9);
  EXPECT_EQ(y->ScreenY(0.0), t);
  // smaller: y for a landscape image, x for a portrait one (the same rays).
  auto wide = ParseCamera(base + R"("fov_axis":"smaller", "width":64, "height":32})", "s");
  auto tall = ParseCamera(base + R"("fov_axis":"smaller", "width":32, "height":64})", "s");
  auto tall_x = ParseCamera(base + R"("width":32, "height":64})", "tx");
  ASSERT_TRUE(wide.ok() && tall.ok() && tall_x.ok());
  EXPECT_EQ(wide->scale_x(), y->scale_x());
  EXPECT_EQ(wide->scale_y(), y->scale_y());
  EXPECT_EQ(tall->scale_x(), tall_x->scale_x());
  EXPECT_EQ(tall->scale_y(), tall_x->scale_y());
  // --size keeps the vertical field of view of a fov_axis y camera.
  Run r = Render({{"--cam", Write("fy.json", base + R"("fov_axis":"y", "width":64, "height":32})")},
                  {"--size", "32x32"}, {"--save-cam", Path("fy_used.json")}});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  auto used = LoadCamera(Path("fy_used.json"));
  ASSERT_TRUE(used.ok());
  EXPECT_EQ(used->fov_axis, FovAxis::kY);
  EXPECT_EQ(used->scale_y(), t);
  EXPECT_EQ(used->width, 32);
}

// A lens as DCCs give it: focal length and the sensor's (film back's) width,
// spanning the image's width: the rays of fov = 2 atan(sensor / (2 focal)).
TEST_F(CameraWorkflowTest, FocalLengthAndSensorWidth) {
  const std::string pose =
      R"({"position":[3,4,17], "look_at":[0.5,-0.25,0], "width":64, "height":48, )";
  const double fov = 2 * std::atan(36.0 / (2 * 50.0)) * 180 / M_PI;
  auto by_fov = ParseCamera(pose + "\"fov_deg\":" + std::to_string(fov) + "}", "fov");
  auto lens = ParseCamera(pose + R"("focal_length_mm":50, "sensor_width_mm":36})", "lens");
  auto aperture = ParseCamera(pose + R"("focal_length_mm":50, "aperture_mm":36})", "aperture");
  ASSERT_TRUE(by_fov.ok() && lens.ok() && aperture.ok()) << lens.status().ToString();
  EXPECT_NEAR(lens->fov_deg, 39.5977, 1e-4);  // Blender's 50 mm on its 36 mm sensor
  EXPECT_DOUBLE_EQ(lens->scale_x(), 36.0 / 100.0);
  EXPECT_EQ(lens->scale_x(), aperture->scale_x());
  EXPECT_NEAR(lens->scale_x(), by_fov->scale_x(), 1e-6);
  // vdb_render's default lens (-focal 50 -aperture 41.2) is its default -fov 44.8.
  auto vdb = ParseCamera(pose + R"("focal_length_mm":50, "aperture_mm":41.2})", "vdb");
  ASSERT_TRUE(vdb.ok());
  EXPECT_NEAR(vdb->HorizontalFovDeg(), 44.8, 0.05);
  // The same image as the fov_deg it stands for, saved as such.
  Run a = Render(
      {{"--cam", Write("lens.json", pose + R"("focal_length_mm":50, "sensor_width_mm":36})")},
       {"--save-cam", Path("lens_used.json")}});
  ASSERT_TRUE(a.status.ok()) << a.status.ToString();
  Run b = Render({{"--cam", Path("lens_used.json")}});
  ASSERT_TRUE(b.status.ok()) << b.status.ToString();
  EXPECT_GT(Hits(a.out), 300);
  EXPECT_TRUE(SameImage(a.out, b.out));
  auto refuse = [&](const std::string& json, const std::string& what) {
    auto c = ParseCamera(json, "c.json");
    ASSERT_FALSE(c.ok()) << json;
    EXPECT_NE(c.status().message().find(what), std::string::npos) << c.status().ToString();
    EXPECT_NE(c.status().message().find("c.json"), std::string::npos) << c.status().ToString();
  };
  refuse(pose + R"("focal_length_mm":50})", "needs the sensor's width: sensor_width_mm");
  refuse(pose + R"("sensor_width_mm":36, "fov_deg":40})", "needs focal_length_mm");
  refuse(pose + R"("focal_length_mm":50, "sensor_width_mm":36, "fov_deg":40})", "give one");
  refuse(pose + R"("focal_length_mm":50, "sensor_width_mm":36, "aperture_mm":36})", "give one");
  refuse(pose + R"("focal_length_mm":0, "sensor_width_mm":36})",
         "'focal_length_mm' must be a positive");
  refuse(pose + R"("focal_length_mm":50, "sensor_width_mm":-1})",
         "'sensor_width_mm' must be a positive");
  refuse(
      pose +
          R"("projection":"orthographic", "ortho_width":2, "focal_length_mm":50, "sensor_width_mm":36})",
      "only applies to a perspective projection");
}

// Houdini's matrices act on row vectors (the position in the last row): with
// "row_major": true they are the transpose of the column-vector matrix and
// render its image bit for bit; without it the error says to transpose.
TEST_F(CameraWorkflowTest, RowMajorMatrix) {
  const std::string rest = R"(, "fov_deg":40, "width":48, "height":48})";
  const std::string column = R"({"camera_to_world":[0,0,1,20, 0,1,0,0, -1,0,0,0, 0,0,0,1])";
  const std::string row = R"({"camera_to_world":[0,0,-1,0, 0,1,0,0, 1,0,0,0, 20,0,0,1])";
  auto c = ParseCamera(column + rest, "column");
  auto r = ParseCamera(row + R"(, "row_major":true)" + rest, "row");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->forward(), glm::dvec3(-1, 0, 0));
  EXPECT_EQ(r->position, glm::dvec3(20, 0, 0));
  EXPECT_EQ(r->ToJson(), c->ToJson());
  Run a = Render({{"--cam", Write("column.json", column + rest)}});
  Run b = Render({{"--cam", Write("row.json", row + R"(, "row_major":true)" + rest)}});
  ASSERT_TRUE(a.status.ok() && b.status.ok()) << b.status.ToString();
  EXPECT_GT(Hits(a.out), 100);
  EXPECT_TRUE(SameImage(a.out, b.out));
  auto transposed = ParseCamera(row + rest, "h.json");
  ASSERT_FALSE(transposed.ok());
  EXPECT_NE(transposed.status().message().find("h.json"), std::string::npos);
  EXPECT_NE(transposed.status().message().find("transpose it, or set \"row_major\": true"),
            std::string::npos)
      << transposed.status().ToString();
  auto wrong_flag = ParseCamera(column + R"(, "row_major":true)" + rest, "w.json");
  ASSERT_FALSE(wrong_flag.ok());
  EXPECT_NE(wrong_flag.status().message().find("leave row_major out"), std::string::npos)
      << wrong_flag.status().ToString();
  auto no_matrix =
      ParseCamera(R"({"position":[0,0,20], "look_at":[0,0,0], "row_major":true)" + rest, "n.json");
  ASSERT_FALSE(no_matrix.ok());
  EXPECT_NE(no_matrix.status().message().find("'row_major' only applies to camera_to_world"),
            std::string::npos)
      << no_matrix.status().ToString();
}

// --size gives the size of a camera JSON without width and height (one
// camera or an array); without --size the error names both ways.
TEST_F(CameraWorkflowTest, SizeFillsAMissingWidthAndHeight) {
  const std::string sizeless = R"({"position":[3,4,17], "look_at":[0.5,-0.25,0], "fov_deg":38})";
  Run r = Render({{"--cam", Write("sizeless.json", sizeless)}, {"--size", "40x30"}});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.out.width, 40);
  EXPECT_EQ(r.out.height, 30);
  EXPECT_GT(Hits(r.out), 100);
  // The same image as the camera with the size written in.
  Run full = Render(
      {{"--cam",
        Write(
            "sized.json",
            R"({"position":[3,4,17], "look_at":[0.5,-0.25,0], "fov_deg":38, "width":40, "height":30})")}});
  ASSERT_TRUE(full.status.ok());
  EXPECT_TRUE(SameImage(r.out, full.out));
  Run seq = Render({{"--cam", Write("sizeless_seq.json", "[" + sizeless + "," + sizeless + "]")},
                    {"--size", "24x16"},
                    {"--frames", "2"}});
  ASSERT_TRUE(seq.status.ok()) << seq.status.ToString();
  EXPECT_EQ(seq.out.width, 24);
  Run missing = Render({{"--cam", Write("sizeless2.json", sizeless)}});
  ASSERT_FALSE(missing.status.ok());
  EXPECT_NE(missing.status.message().find(
                "field 'width' is missing (give width and height, or vox-render --size WxH)"),
            std::string::npos)
      << missing.status.ToString();
  EXPECT_NE(missing.status.message().find(Path("sizeless2.json")), std::string::npos);
}

}  // namespace
}  // namespace vox

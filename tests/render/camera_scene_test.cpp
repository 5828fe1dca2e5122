// cam.json and scene.json: parsing, validation messages, ray geometry.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <string>

#include "render/camera.h"
#include "render/scene.h"

namespace vox {
namespace {

const char* kGood =
    R"({"position":[0,0,10], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":90, "width":4, "height":2, "projection":"perspective"})";

void ExpectCameraError(const std::string& json, const std::string& field) {
  auto cam = ParseCamera(json, "cam.json");
  ASSERT_FALSE(cam.ok()) << json;
  EXPECT_EQ(cam.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(cam.status().message().find("cam.json"), std::string::npos) << cam.status().message();
  EXPECT_NE(cam.status().message().find(field), std::string::npos) << cam.status().message();
}

TEST(CameraTest, ParsesAndFramesPixelCentres) {
  auto cam = ParseCamera(kGood, "cam.json");
  ASSERT_TRUE(cam.ok()) << cam.status().ToString();
  EXPECT_EQ(cam->width, 4);
  // Row 0 is the top: its rays point up; column 0 points left.
  WorldRay top_left = cam->PixelRay(0.5, 0.5);
  EXPECT_GT(top_left.dir.y, 0);
  EXPECT_LT(top_left.dir.x, 0);
  // Horizontal fov 90: the left image edge is 45 degrees off axis.
  WorldRay edge = cam->PixelRay(0.0, 1.0);
  EXPECT_NEAR(std::acos(glm::dot(edge.dir, glm::dvec3(0, 0, -1))), M_PI / 4, 1e-12);
  // The centre of the image looks at look_at.
  WorldRay centre = cam->PixelRay(2.0, 1.0);
  EXPECT_NEAR(centre.dir.z, -1.0, 1e-15);
  // Vertical extent follows the aspect ratio: top edge at atan(0.5).
  WorldRay top = cam->PixelRay(2.0, 0.0);
  EXPECT_NEAR(std::atan2(top.dir.y, -top.dir.z), std::atan(0.5), 1e-12);
}

TEST(CameraTest, Orthographic) {
  auto cam = ParseCamera(
      R"({"position":[1,2,10], "look_at":[1,2,0], "ortho_width":8, "width":8, "height":4, "projection":"orthographic"})",
      "cam.json");
  ASSERT_TRUE(cam.ok()) << cam.status().ToString();
  for (int i = 0; i < 8; ++i) {
    WorldRay r = cam->PixelRay(i + 0.5, 0.5);
    EXPECT_NEAR(r.origin.x, 1 - 4 + i + 0.5, 1e-12);
    EXPECT_NEAR(r.origin.y, 2 + 2 - 0.5, 1e-12);
    EXPECT_EQ(r.dir, glm::dvec3(0, 0, -1));
  }
}

// Refraction needs a depth and a transmitting material, the default or a region's.
TEST(SceneTest, RefractsOnlyWithDepthAndATransmittingMaterial) {
  const auto refracts = [](const char* json) {
    auto s = ParseScene(json, "scene.json");
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return s.ok() && SceneRefracts(*s);
  };
  EXPECT_FALSE(refracts("{}"));
  EXPECT_FALSE(refracts(R"({"material": {"transmit": 0.5}, "max_depth": 0})"));
  EXPECT_TRUE(refracts(R"({"material": {"transmit": 0.5}, "max_depth": 2})"));
  EXPECT_FALSE(refracts(R"({"material": {"reflect": 0.5}, "max_depth": 2})"));
  EXPECT_TRUE(refracts(R"({"materials": [{"box": {"min": [0,0,0], "max": [1,1,1]},
                                          "transmit": 0.2}], "max_depth": 1})"));
}

TEST(CameraTest, ErrorsNameTheField) {
  ExpectCameraError(R"({"look_at":[0,0,0], "fov_deg":40, "width":4, "height":4})", "position");
  ExpectCameraError(R"({"position":[0,0,1], "fov_deg":40, "width":4, "height":4})", "look_at");
  ExpectCameraError(R"({"position":[0,0,1], "look_at":[0,0,0], "width":4, "height":4})", "fov_deg");
  ExpectCameraError(R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "height":4})",
                    "width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":"4", "height":4})", "width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":0, "height":4})", "width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":0})", "height");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4.5, "height":4})", "width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "up":[0,0,2], "fov_deg":40, "width":4, "height":4})",
      "up");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "up":[0,0,0], "fov_deg":40, "width":4, "height":4})",
      "up");
  ExpectCameraError(
      R"({"position":[1e999,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4})",
      "1e999");
  ExpectCameraError(
      R"({"position":["NaN",0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4})",
      "position[0]");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,1], "fov_deg":40, "width":4, "height":4})", "look_at");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":180, "width":4, "height":4})",
      "fov_deg");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4, "projection":"fisheye"})",
      "projection");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "width":4, "height":4, "projection":"orthographic"})",
      "ortho_width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "ortho_width":-1, "width":4, "height":4, "projection":"orthographic"})",
      "ortho_width");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4, "fov":3})",
      "fov");
  ExpectCameraError(
      R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4,)", "JSON");
  ExpectCameraError(R"([1,2,3])", "object");
}

TEST(CameraTest, LoadNamesMissingFile) {
  auto cam = LoadCamera("/nonexistent/cam.json");
  ASSERT_FALSE(cam.ok());
  EXPECT_EQ(cam.status().code(), StatusCode::kNotFound);
  EXPECT_NE(cam.status().message().find("/nonexistent/cam.json"), std::string::npos);
}

TEST(CameraTest, DefaultCameraSeesTheWholeBox) {
  glm::dvec3 lo(-3, 10, 2), hi(5, 14, 40);
  Camera cam = DefaultCamera(lo, hi, 200, 100);
  // Every corner projects inside the image.
  for (int c = 0; c < 8; ++c) {
    glm::dvec3 p((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y, (c & 4) ? hi.z : lo.z);
    glm::dvec3 d = p - cam.position;
    double z = glm::dot(d, cam.forward());
    ASSERT_GT(z, 0);
    double sx = glm::dot(d, cam.right()) / z / std::tan(cam.fov_deg * M_PI / 360);
    double sy = glm::dot(d, cam.true_up()) / z / std::tan(cam.fov_deg * M_PI / 360) * 2;
    EXPECT_LT(std::fabs(sx), 1.0);
    EXPECT_LT(std::fabs(sy), 1.0);
  }
}

void ExpectSceneError(const std::string& json, const std::string& field) {
  auto s = ParseScene(json, "scene.json");
  ASSERT_FALSE(s.ok()) << json;
  EXPECT_NE(s.status().message().find("scene.json"), std::string::npos) << s.status().message();
  EXPECT_NE(s.status().message().find(field), std::string::npos) << s.status().message();
}

TEST(SceneTest, DefaultsAndFullParse) {
  auto d = ParseScene("{}", "scene.json");
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->default_lights);
  EXPECT_EQ(d->samples_per_pixel, 1);
  auto s = ParseScene(R"({
    "background": {"top":[1,0,0], "bottom":[0,0,1]}, "ambient":[0.1,0.1,0.1],
    "lights": [{"type":"directional", "direction":[0,-2,0], "color":[1,1,1], "intensity":2, "shadows":false},
               {"type":"point", "position":[1,2,3]}],
    "material": {"color":[1,0.5,0.25], "diffuse":0.7, "specular":0.1, "shininess":8, "reflect":0.2, "transmit":0.3, "ior":1.33},
    "materials": [{"box":{"min":[0,0,0],"max":[1,1,1]}, "reflect":0.7, "diffuse":0}],
    "volume": {"absorption":0.2, "scattering":0.7},
    "max_depth": 3, "samples_per_pixel": 4})",
                      "scene.json");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_FALSE(s->default_lights);
  ASSERT_EQ(s->lights.size(), 2u);
  EXPECT_EQ(s->lights[0].direction, glm::dvec3(0, -1, 0));
  EXPECT_FALSE(s->lights[0].shadows);
  EXPECT_TRUE(s->lights[1].shadows);
  EXPECT_EQ(s->lights[1].type, Light::Type::kPoint);
  EXPECT_DOUBLE_EQ(s->material.ior, 1.33);
  EXPECT_DOUBLE_EQ(s->MaterialAt({0.5, 0.5, 0.5}).reflect, 0.7);
  EXPECT_DOUBLE_EQ(s->MaterialAt({0.5, 0.5, 0.5}).transmit, 0.3);  // inherited from "material"
  EXPECT_DOUBLE_EQ(s->MaterialAt({2, 0.5, 0.5}).reflect, 0.2);
  EXPECT_EQ(s->max_depth, 3);
  EXPECT_EQ(s->samples_per_pixel, 4);
  auto none = ParseScene(R"({"lights": []})", "scene.json");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->default_lights);
  EXPECT_TRUE(none->lights.empty());
  // ToJson round-trips.
  auto again = ParseScene(s->ToJson(), "again.json");
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->ToJson(), s->ToJson());
}

TEST(SceneTest, ErrorsNameTheField) {
  ExpectSceneError(R"({"lights": {}})", "lights");
  ExpectSceneError(R"({"lights": [{"direction":[0,1,0]}]})", "lights[0].type");
  ExpectSceneError(R"({"lights": [{"type":"spot"}]})", "lights[0].type");
  ExpectSceneError(R"({"lights": [{"type":"directional"}]})", "lights[0].direction");
  ExpectSceneError(R"({"lights": [{"type":"directional", "direction":[0,0,0]}]})",
                   "lights[0].direction");
  ExpectSceneError(R"({"lights": [{"type":"point", "position":[0,0]}]})", "lights[0].position");
  ExpectSceneError(R"({"lights": [{"type":"point", "position":[0,0,0], "shadows":1}]})",
                   "lights[0].shadows");
  ExpectSceneError(R"({"material": {"reflect": 2}})", "material.reflect");
  ExpectSceneError(R"({"material": {"reflect": 0.6, "transmit": 0.6}})", "material.transmit");
  ExpectSceneError(R"({"material": {"ior": 0}})", "material.ior");
  ExpectSceneError(R"({"material": {"colour": [1,1,1]}})", "material.colour");
  ExpectSceneError(R"({"material": {"color": [1,-1,1]}})", "material.color");
  ExpectSceneError(R"({"materials": [{"reflect":1}]})", "materials[0].box");
  ExpectSceneError(R"({"volume": {"absorption": -1}})", "volume.absorption");
  ExpectSceneError(R"({"max_depth": 100})", "max_depth");
  ExpectSceneError(R"({"samples_per_pixel": 0})", "samples_per_pixel");
  ExpectSceneError(R"({"background": "blue"})", "background");
  ExpectSceneError(R"({"backgruond": [0,0,0]})", "backgruond");
}

}  // namespace
}  // namespace vox

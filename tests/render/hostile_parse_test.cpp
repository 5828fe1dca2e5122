// Valid-looking but hostile camera and scene files: a key given twice is an
// error naming the key and the file (whichever value a parser keeps, the
// file is ambiguous); a perspective pixel must span at least 1e-12 radians.
#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "render/camera.h"
#include "render/scene.h"

namespace vox {
namespace {

std::string Cam(const std::string& fov, const std::string& extra = "") {
  return R"({"position":[1,2,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":)" + fov +
         R"(,"width":640,"height":480)" + extra + "}";
}

TEST(HostileParse, DuplicateKeysAreRefused) {
  auto c = ParseCamera(Cam("40", R"(,"fov_deg":50)"), "cam.json");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(c.status().message().find("cam.json: key 'fov_deg' appears twice"), std::string::npos)
      << c.status().ToString();
  // Nested objects have their own keys: the same name at two levels is fine,
  // twice in a nested object is not.
  auto s = ParseScene(R"({"background":{"top":[1,1,1],"bottom":[0,0,0],"top":[0,0,0]}})",
                      "scene.json");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("scene.json: key 'top' appears twice"), std::string::npos)
      << s.status().ToString();
  auto l = ParseScene(R"({"lights":[{"type":"point","position":[0,0,0],"color":[1,1,1]},
                                   {"type":"point","position":[1,0,0],"color":[1,1,1]}]})",
                      "scene.json");
  EXPECT_TRUE(l.ok()) << "the same keys in two array elements are not duplicates: "
                      << l.status().ToString();
  EXPECT_TRUE(ParseCamera(Cam("40"), "cam.json").ok());
}

// 150,000 keys would take minutes with a linear search per key; a set per
// object finds the duplicate at the end at once.
TEST(HostileParse, ManyKeysAreCheckedInNLogN) {
  std::string extra;
  for (int i = 0; i < 150000; ++i) extra += ",\"k" + std::to_string(i) + "\":0";
  extra += ",\"k7\":1";
  const auto t0 = std::chrono::steady_clock::now();
  auto c = ParseCamera(Cam("40", extra), "cam.json");
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("key 'k7' appears twice"), std::string::npos)
      << c.status().ToString();
  EXPECT_LT(seconds, 10.0);
}

TEST(HostileParse, MinimumAngularPixelSize) {
  for (const char* fov : {"1e-300", "1e-12", "3e-8"}) {
    auto c = ParseCamera(Cam(fov), "cam.json");
    ASSERT_FALSE(c.ok()) << fov;
    EXPECT_NE(c.status().message().find("fov_deg' is too small"), std::string::npos)
        << c.status().ToString();
    EXPECT_NE(c.status().message().find("1e-12 radians per pixel"), std::string::npos)
        << c.status().ToString();
  }
  // 1e-6 degrees over 640 pixels: 2.7e-11 radians per pixel, distinguishable.
  auto ok = ParseCamera(Cam("1e-6"), "cam.json");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_NE(ok->PixelRay(0.5, 0.5).dir.x, ok->PixelRay(639.5, 0.5).dir.x);
}

}  // namespace
}  // namespace vox

// vox-info's transform as vdb_print lays it out (OpenVDB's
// Transform::print): the index-to-world matrix acting on row vectors, a row
// a line, the translation in the last row; and the world bounding box of the
// occupied voxels, as the renderer frames it (WorldBounds).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <glm/gtc/matrix_transform.hpp>

#include "render/grid_transform.h"
#include "storage/store_info.h"
#include "tests/render/store_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

class InfoLayoutTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vox_info_layout_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& n) const { return (dir_ / n).string(); }
  fs::path dir_;
};

TEST_F(InfoLayoutTest, TransformRowsAndWorldBox) {
  // A 32^3 grid of voxels 0.5, translated by (1, -2, 3.25): a shell.
  StoreMeta meta = testing::TestMeta(5, GridClass::kLevelSet, 0.5);
  meta.brick_level = 2;
  meta.origin = {-16, -16, -16};
  meta.index_to_world = glm::translate(glm::dmat4(1.0), glm::dvec3(1, -2, 3.25)) *
                        glm::scale(glm::dmat4(1.0), glm::dvec3(0.5));
  ASSERT_TRUE(
      testing::WriteStore(Path("store"), meta, testing::ShellVoxels(32, glm::dvec3(16), 8, 10)).ok());
  auto info = InspectStore(Path("store"), false);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  const std::string text = FormatStoreInfo(*info);
  EXPECT_NE(text.find("  index to world:\n"
                      "     [0.5, 0, 0, 0]\n"
                      "     [0, 0.5, 0, 0]\n"
                      "     [0, 0, 0.5, 0]\n"
                      "     [1, -2, 3.25, 1]\n"),
            std::string::npos)
      << text;
  glm::dvec3 lo, hi;
  WorldBounds(info->meta, &lo, &hi);
  char want[256];
  snprintf(want, sizeof want, "  world bbox:      (%.9g, %.9g, %.9g) -> (%.9g, %.9g, %.9g)\n",
           lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
  EXPECT_NE(text.find(want), std::string::npos) << text;
  // The shell's box: index -10..10 (voxels 0.5, each +-0.5 voxel), moved.
  EXPECT_NEAR(lo.x, 1 + (-10 - 0.5) * 0.5, 1e-9);
  EXPECT_NEAR(hi.z, 3.25 + (10 + 0.5) * 0.5, 1e-9);
}

}  // namespace
}  // namespace vox

// Colour sampling (ingest/internal/color.h) against OpenVDB: the colour
// grid's own value where it shares the main grid's transform, and
// openvdb::tools::BoxSampler at the voxel's world position where it does not.
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include "ingest/internal/color.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::NewColorSource;
using openvdb::Coord;

template <class CGridT>
typename CGridT::Ptr Gradient(const openvdb::math::Transform::Ptr& xform) {
  using V = typename CGridT::ValueType;
  auto g = CGridT::create(V(0.25, 0.5, 0.75));
  g->setTransform(xform);
  g->setName("rgb");
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int x = -20; x < 20; ++x)
    for (int y = -20; y < 20; ++y)
      for (int z = -20; z < 20; ++z)
        if ((x + 2 * y + 3 * z) % 5 != 0)  // leave holes: background reads too
          g->tree().setValue(Coord(x, y, z), V(u(rng), u(rng), u(rng)));
  return g;
}

class ColorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  // The colour grid written to a file and read back with delayed loading,
  // as the ingest reads it.
  openvdb::GridBase::Ptr RoundTrip(const openvdb::GridBase::Ptr& g) {
    std::string path = dir_.File("c" + std::to_string(files_++) + ".vdb");
    testutil::WriteVdb(path, {g});
    files_open_.push_back(std::make_unique<openvdb::io::File>(path));
    files_open_.back()->open(true);
    return files_open_.back()->readGrid("rgb");
  }

  template <class CGridT>
  void Check(const openvdb::math::Transform::Ptr& main, const openvdb::math::Transform::Ptr& cx,
             bool exact) {
    auto truth = Gradient<CGridT>(cx);
    auto source = NewColorSource(RoundTrip(truth), *main);
    ASSERT_NE(source, nullptr);
    auto reader = source->NewReader();
    auto acc = truth->getConstAccessor();
    for (int x = -12; x <= 12; ++x)
      for (int y = -12; y <= 12; y += 2)
        for (int z = -12; z <= 12; z += 3) {
          const Coord ijk(x, y, z);
          const glm::vec3 got = reader->At(ijk);
          openvdb::Vec3d want;
          if (exact) {
            want = openvdb::Vec3d(acc.getValue(ijk));
          } else {
            const openvdb::Vec3d p = cx->worldToIndex(main->indexToWorld(ijk));
            want = openvdb::Vec3d(openvdb::tools::BoxSampler::sample(acc, p));
          }
          for (int c = 0; c < 3; ++c)
            if (exact)
              ASSERT_EQ(got[c], float(want[c])) << ijk;
            else
              ASSERT_NEAR(got[c], want[c], 1e-5) << ijk << " channel " << c;
        }
  }

  testutil::TempDir dir_;
  int files_ = 0;
  std::vector<std::unique_ptr<openvdb::io::File>> files_open_;
};

TEST_F(ColorTest, SameTransformReadsTheGridsValue) {
  auto xf = openvdb::math::Transform::createLinearTransform(0.5);
  Check<openvdb::Vec3fGrid>(xf, xf->copy(), true);
  Check<openvdb::Vec3dGrid>(xf, xf->copy(), true);
}

TEST_F(ColorTest, OtherTransformSamplesAsBoxSampler) {
  auto main = openvdb::math::Transform::createLinearTransform(0.5);
  auto coarse = openvdb::math::Transform::createLinearTransform(0.7);
  coarse->postTranslate(openvdb::Vec3d(0.13, -0.4, 0.9));
  coarse->postRotate(0.3, openvdb::math::Y_AXIS);
  Check<openvdb::Vec3fGrid>(main, coarse, false);
  Check<openvdb::Vec3dGrid>(main, coarse, false);
}

TEST_F(ColorTest, OnlyVec3GridsAreColourSources) {
  auto xf = openvdb::math::Transform::createLinearTransform(1.0);
  EXPECT_EQ(NewColorSource(openvdb::FloatGrid::create(), *xf), nullptr);
  EXPECT_EQ(NewColorSource(openvdb::Vec3IGrid::create(), *xf), nullptr);
}

}  // namespace
}  // namespace vox

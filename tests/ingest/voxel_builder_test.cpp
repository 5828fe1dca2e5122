// The voxel builder (ingest/internal/voxel_builder.h): normals are OpenVDB's
// own index-space central-difference gradient (math::ISGradient<CD_2ND>),
// normalised, at leaf voxels (also on leaf faces, where the neighbour is in
// another leaf or a tile) and at tile voxels; the leaf path and the tile path
// build bit-identical voxels; densities and colours are the grids' values.
#include <cmath>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/internal/voxel_builder.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::NewColorSource;
using ingest_internal::VoxelBuilder;
using openvdb::Coord;

class VoxelBuilderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  // `g` written to a file and read back with delayed loading, as the ingest reads it.
  template <class GridT>
  typename GridT::Ptr RoundTrip(typename GridT::Ptr g, openvdb::GridBase::Ptr color = nullptr) {
    std::string path = dir_.File("g" + std::to_string(files_++) + ".vdb");
    openvdb::GridPtrVec grids{g};
    if (color) grids.push_back(color);
    testutil::WriteVdb(path, grids);
    open_.push_back(std::make_unique<openvdb::io::File>(path));
    open_.back()->open(true);
    if (color) color_ = open_.back()->readGrid(color->getName());
    return openvdb::gridPtrCast<GridT>(open_.back()->readGrid(g->getName()));
  }

  testutil::TempDir dir_;
  int files_ = 0;
  std::vector<std::unique_ptr<openvdb::io::File>> open_;
  openvdb::GridBase::Ptr color_;
};

template <class GridT>
glm::vec3 OpenVdbNormal(const GridT& g, const Coord& ijk) {
  auto acc = g.getConstAccessor();
  const auto grad = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc, ijk);
  const double len = grad.length();
  if (!(len > 0)) return glm::vec3(0.0f);
  return glm::vec3(float(grad[0] / len), float(grad[1] / len), float(grad[2] / len));
}

template <class GridT>
void CheckLevelSet(const GridT& truth, const GridT& loaded) {
  const int64_t rmin[3] = {-40, -50, -60};
  VoxelBuilder<GridT> builder(loaded, /*level_set=*/true, nullptr, rmin);
  uint64_t on_face = 0, voxels = 0;
  for (auto it = loaded.constTree().cbeginLeaf(); it; ++it) {
    builder.BeginLeaf(it.getLeaf());
    for (auto m = it->getValueMask().beginOn(); m; ++m) {
      const Coord ijk = it->offsetToGlobalCoord(m.pos());
      const auto v = builder.LeafValue(m.pos());
      ASSERT_EQ(v, truth.tree().getValue(ijk));
      const BrickVoxel leaf = builder.FromLeaf(m.pos(), v);
      EXPECT_EQ(int64_t(leaf.x), ijk.x() - rmin[0]);
      EXPECT_EQ(int64_t(leaf.y), ijk.y() - rmin[1]);
      EXPECT_EQ(int64_t(leaf.z), ijk.z() - rmin[2]);
      const glm::vec3 want = OpenVdbNormal(truth, ijk);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(leaf.attr.normal[c], want[c], 1e-6) << ijk;
      // One builder: the tile path gives the very same voxel.
      const BrickVoxel tile = builder.FromTile(ijk, v);
      ASSERT_EQ(tile.x, leaf.x);
      ASSERT_EQ(tile.y, leaf.y);
      ASSERT_EQ(tile.z, leaf.z);
      for (int c = 0; c < 3; ++c) ASSERT_EQ(tile.attr.normal[c], leaf.attr.normal[c]) << ijk;
      const Coord l = ijk - it->origin();
      if (l.x() % 7 == 0 || l.y() % 7 == 0 || l.z() % 7 == 0) ++on_face;
      ++voxels;
    }
  }
  EXPECT_GT(voxels, 1000u);
  EXPECT_GT(on_face, 100u);  // neighbours read from other leaves
}

TEST_F(VoxelBuilderTest, LevelSetNormalsAreOpenVdbsGradient) {
  auto f = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      9.5f, openvdb::Vec3f(1.3f, -2, 0.5f),
                                                                    1.0f, 3.0f);
  f->setName("f");
  CheckLevelSet(*f, *RoundTrip<openvdb::FloatGrid>(f));
  auto d = openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(7.0, openvdb::Vec3d(0.0),
                                                                     1.0, 3.0);
  d->setName("d");
  CheckLevelSet(*d, *RoundTrip<openvdb::DoubleGrid>(d));
}

TEST_F(VoxelBuilderTest, TileVoxelsAndLeafFacesOnTiles) {
  // An inside tile (value -2) beside a leaf whose values ramp along x.
  auto g = openvdb::FloatGrid::create(3.0f);
  g->setName("t");
  g->setGridClass(openvdb::GRID_LEVEL_SET);
  g->tree().addTile(1, Coord(0, 0, 0), -2.0f, true);
  for (int x = 8; x < 16; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z)
        g->tree().setValue(Coord(x, y, z), float(x - 12) * 0.5f + 0.1f * float(y));
  auto loaded = RoundTrip<openvdb::FloatGrid>(g);
  const int64_t rmin[3] = {0, 0, 0};
  VoxelBuilder<openvdb::FloatGrid> builder(*loaded, true, nullptr, rmin);
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) {
        const Coord ijk(x, y, z);
        const BrickVoxel v = builder.FromTile(ijk, -2.0f);
        const glm::vec3 want = OpenVdbNormal(*g, ijk);
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(v.attr.normal[c], want[c], 1e-6) << ijk;
      }
  // Leaf voxels at x = 8 read their -x neighbour from the tile.
  const auto* leaf = loaded->constTree().probeConstLeaf(Coord(8, 0, 0));
  ASSERT_NE(leaf, nullptr);
  builder.BeginLeaf(leaf);
  for (openvdb::Index n = 0; n < 64; ++n) {  // the x = 8 face
    const Coord ijk = leaf->offsetToGlobalCoord(n);
    const BrickVoxel v = builder.FromLeaf(n, builder.LeafValue(n));
    const glm::vec3 want = OpenVdbNormal(*g, ijk);
    for (int c = 0; c < 3; ++c) ASSERT_NEAR(v.attr.normal[c], want[c], 1e-6) << ijk;
  }
  // A flat region has no gradient: normal 0.
  auto flat = openvdb::FloatGrid::create(-1.0f);
  flat->setName("flat");
  flat->tree().setValue(Coord(3, 3, 3), -1.0f);
  auto lflat = RoundTrip<openvdb::FloatGrid>(flat);
  VoxelBuilder<openvdb::FloatGrid> fb(*lflat, true, nullptr, rmin);
  EXPECT_EQ(fb.FromTile(Coord(3, 3, 3), -1.0f).attr.normal, glm::vec3(0.0f));
}

TEST_F(VoxelBuilderTest, DensitiesAndColours) {
  auto fog = openvdb::FloatGrid::create(0.0f);
  fog->setName("fog");
  auto rgb = openvdb::Vec3fGrid::create(openvdb::Vec3f(0.0f));
  rgb->setName("rgb");
  for (int i = 0; i < 200; ++i) {
    const Coord c(i % 13, (i * 7) % 11, (i * 3) % 17);
    fog->tree().setValue(c, 0.01f * float(i + 1));
    rgb->tree().setValue(c, openvdb::Vec3f(float(i) / 200, 1.0f - float(i) / 200, 0.5f));
  }
  auto loaded = RoundTrip<openvdb::FloatGrid>(fog, rgb);
  auto source = NewColorSource(color_, loaded->transform());
  ASSERT_NE(source, nullptr);
  auto reader = source->NewReader();
  const int64_t rmin[3] = {0, 0, 0};
  VoxelBuilder<openvdb::FloatGrid> builder(*loaded, false, reader.get(), rmin);
  uint64_t n_voxels = 0;
  for (auto it = loaded->constTree().cbeginLeaf(); it; ++it) {
    builder.BeginLeaf(it.getLeaf());
    for (auto m = it->getValueMask().beginOn(); m; ++m, ++n_voxels) {
      const Coord ijk = it->offsetToGlobalCoord(m.pos());
      const BrickVoxel v = builder.FromLeaf(m.pos(), builder.LeafValue(m.pos()));
      EXPECT_EQ(v.attr.density, fog->tree().getValue(ijk));
      const openvdb::Vec3f want = rgb->tree().getValue(ijk);
      EXPECT_EQ(v.attr.color, glm::vec3(want[0], want[1], want[2])) << ijk;
      const BrickVoxel t = builder.FromTile(ijk, fog->tree().getValue(ijk));
      EXPECT_EQ(t.attr.density, v.attr.density);
      EXPECT_EQ(t.attr.color, v.attr.color);
    }
  }
  EXPECT_EQ(n_voxels, fog->activeVoxelCount());
}

}  // namespace
}  // namespace vox

// The compact topology reader (ingest/internal/vdb_topology.h) against
// OpenVDB's own tree of the same file: the same leaves (origins, active
// counts, value masks, every value), the same value (leaf, tile at any level,
// background) at every voxel around the grid's content, the same active
// tiles and active voxel count; for float and double grids, half-float
// files, several compressions; corrupt files are errors, not crashes.
#include <cstdio>
#include <map>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/internal/vdb_layout.h"
#include "ingest/internal/vdb_topology.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::CompactTopology;
using ingest_internal::ReadVdbLayout;
using openvdb::Coord;

class VdbTopologyTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  template <class GridT>
  void Check(typename GridT::Ptr g, uint32_t compression, bool half) {
    using ValueT = typename GridT::ValueType;
    SCOPED_TRACE("compression " + std::to_string(compression) + (half ? " half" : ""));
    g->setSaveFloatAsHalf(half);
    const std::string path = dir_.File("t" + std::to_string(files_++) + ".vdb");
    {
      openvdb::io::File f(path);
      f.setCompression(compression);
      f.write({g});
    }
    // OpenVDB's reading of the same file is the truth (half floats are rounded).
    openvdb::io::File f(path);
    f.open(false);
    auto truth = openvdb::gridPtrCast<GridT>(f.readGrid(g->getName()));
    ASSERT_TRUE(truth);
    auto layout = ReadVdbLayout(path);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    auto t = CompactTopology<ValueT>::Read(path, *layout, layout->grids[0]);
    ASSERT_TRUE(t.ok()) << t.status().ToString();
    const auto& topo = **t;
    EXPECT_EQ(topo.background(), truth->background());
    EXPECT_EQ(topo.active_voxels(), truth->activeVoxelCount());
    ASSERT_EQ(topo.leaves().size(), truth->tree().leafCount());
    // Leaves: in the tree's order, with the same masks and values.
    std::vector<char> scratch;
    size_t i = 0;
    for (auto it = truth->tree().cbeginLeaf(); it; ++it, ++i) {
      const auto& leaf = topo.leaves()[i];
      ASSERT_EQ(leaf.Origin(), it->origin());
      ASSERT_EQ(leaf.active, it->onVoxelCount());
      ValueT values[512];
      typename CompactTopology<ValueT>::Mask mask;
      topo.ReadLeaf(i, values, &mask, &scratch);
      ASSERT_EQ(mask, it->getValueMask());
      for (int n = 0; n < 512; ++n) ASSERT_EQ(values[n], it->getValue(n)) << it->origin();
      const auto w = topo.Lookup(it->origin().offsetBy(7, 0, 3));
      ASSERT_EQ(w.leaf, int64_t(i));
    }
    // Every voxel of the leaves' bounding box, grown by two leaves, and the
    // corners and centres of every tile: leaf or value.
    openvdb::CoordBBox box;
    for (auto it = truth->tree().cbeginLeaf(); it; ++it) box.expand(it->getNodeBoundingBox());
    box.expand(16);
    std::vector<Coord> probes;
    for (auto c = box.begin(); c; ++c) probes.push_back(*c);
    for (auto it = truth->tree().cbeginValueAll(); it; ++it) {
      if (!it.isTileValue()) continue;
      openvdb::CoordBBox b;
      it.getBoundingBox(b);
      for (const Coord& c : {b.min(), b.max(), Coord::round(b.getCenter()), b.min().offsetBy(-1),
                             b.max().offsetBy(1)})
        probes.push_back(c);
    }
    auto acc = truth->getConstAccessor();
    uint64_t checked = 0;
    for (const Coord& probe : probes) {
      ++checked;
      const Coord* c = &probe;
      const auto w = topo.Lookup(*c);
      const auto* leaf = acc.probeConstLeaf(*c);
      if (leaf) {
        ASSERT_GE(w.leaf, 0) << *c;
        ASSERT_EQ(topo.leaves()[size_t(w.leaf)].Origin(), leaf->origin());
      } else {
        ASSERT_EQ(w.leaf, -1) << *c;
        ASSERT_EQ(w.value, acc.getValue(*c)) << *c;
      }
    }
    EXPECT_GT(checked, 0u);
    // Active tiles: the same boxes and values as OpenVDB's tile iterator.
    std::map<std::array<int, 4>, ValueT> want, got;
    auto it = truth->tree().cbeginValueOn();
    it.setMaxDepth(GridT::TreeType::ValueOnCIter::LEAF_DEPTH - 1);
    for (; it; ++it) {
      if (!it.isTileValue()) continue;
      openvdb::CoordBBox b;
      it.getBoundingBox(b);
      want[{b.min().x(), b.min().y(), b.min().z(), b.dim().x()}] = *it;
    }
    for (const auto& tile : topo.active_tiles())
      got[{tile.box.min().x(), tile.box.min().y(), tile.box.min().z(), tile.box.dim().x()}] =
          tile.value;
    EXPECT_EQ(got, want);
  }

  testutil::TempDir dir_;
  int files_ = 0;
};

template <class GridT>
typename GridT::Ptr SphereWithTiles() {
  auto g = openvdb::tools::createLevelSetSphere<GridT>(20.0f, openvdb::Vec3f(3, -5, 9), 1.0f, 3.0f);
  g->setName("s");
  g->tree().addTile(1, Coord(128, 0, 0), -1.5, true);      // level 1 tile, active
  g->tree().addTile(1, Coord(136, 8, 0), 0.25, false);     // inactive, not background
  g->tree().addTile(2, Coord(256, 0, 0), -2.0, true);      // level 2 tile
  g->tree().addTile(3, Coord(-8192, 0, 0), -0.5, true);    // root tile
  g->tree().addTile(2, Coord(-128, -128, -128), 7.0, false);
  return g;
}

TEST_F(VdbTopologyTest, FloatLevelSetWithTilesEveryCompression) {
  using openvdb::io::COMPRESS_ACTIVE_MASK;
  using openvdb::io::COMPRESS_BLOSC;
  using openvdb::io::COMPRESS_ZIP;
  for (uint32_t c : {uint32_t(openvdb::io::COMPRESS_NONE), uint32_t(COMPRESS_ACTIVE_MASK),
                     uint32_t(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK),
                     uint32_t(COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK)})
    Check<openvdb::FloatGrid>(SphereWithTiles<openvdb::FloatGrid>(), c, false);
}

TEST_F(VdbTopologyTest, HalfFloatAndDouble) {
  const uint32_t c = openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK;
  Check<openvdb::FloatGrid>(SphereWithTiles<openvdb::FloatGrid>(), c, true);
  Check<openvdb::DoubleGrid>(SphereWithTiles<openvdb::DoubleGrid>(), c, false);
  Check<openvdb::DoubleGrid>(SphereWithTiles<openvdb::DoubleGrid>(), c, true);
}

TEST_F(VdbTopologyTest, FogWithScatteredValues) {
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setName("fog");
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  for (int i = 0; i < 3000; ++i)
    g->tree().setValue(Coord((i * 37) % 301 - 150, (i * 11) % 97, (i * 53) % 211 - 40),
                       0.001f * float(i % 977));
  g->tree().setValueOff(Coord(1, 1, 1), 0.75f);  // an inactive value inside a leaf
  Check<openvdb::FloatGrid>(g, openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK,
                            false);
}

TEST_F(VdbTopologyTest, TruncatedFileIsAnError) {
  auto g = SphereWithTiles<openvdb::FloatGrid>();
  const std::string path = dir_.File("cut.vdb");
  testutil::WriteVdb(path, {g});
  auto layout = ReadVdbLayout(path);
  ASSERT_TRUE(layout.ok());
  // Garble the leaf buffers: the grid's bytes after its topology.
  std::FILE* f = std::fopen(path.c_str(), "r+b");
  ASSERT_NE(f, nullptr);
  std::fseek(f, long(layout->grids[0].block_pos + 70), SEEK_SET);
  for (int i = 0; i < 4096; ++i) std::fputc(0xff, f);
  std::fclose(f);
  auto t = CompactTopology<float>::Read(path, *layout, layout->grids[0]);
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.status().ToString().find(path), std::string::npos) << t.status().ToString();
}

}  // namespace
}  // namespace vox

// Brick extraction (ingest/internal/grid_ingest.h) driven directly: the
// bricks handed to the writer hold exactly the voxels OpenVDB reports active
// and occupied (tiles expanded), each brick's voxels strictly in Morton order
// (the writer relies on it and does not sort again), read from the file's
// compact topology, on the leaf-only fast path, the mixed leaf-and-tile path and bricks smaller than a leaf.
#include <algorithm>
#include <cstdlib>
#include <map>
#include <thread>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "core/octree.h"
#include "ingest/internal/grid_ingest.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::Context;
using ingest_internal::IngestGrid;
using openvdb::Coord;
using testutil::Ijk;

class GridIngestTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  // Ingests `g` (written and read back with delayed loading) under `levels`.
  void Run(openvdb::FloatGrid::Ptr g, const std::string& levels) {
    SCOPED_TRACE("levels " + levels);
    const std::string path = dir_.File("g.vdb");
    testutil::WriteVdb(path, {g});
    auto layout = ingest_internal::ReadVdbLayout(path);
    ASSERT_TRUE(layout.ok()) << layout.status().ToString();
    ASSERT_EQ(layout->grids.size(), 1u);
    IngestOptions o;
    o.input = path;
    o.output = dir_.File("unused");
    auto choice = ParseLevels(levels);
    ASSERT_TRUE(choice.ok());
    store_ = testutil::FakeStore();
    WriterFactory factory = store_.Factory();
    stats_ = IngestStats();
    Context cx{o, factory, nullptr, &stats_, *choice, StoreMeta{}, nullptr};
    cx.meta.grid_name = g->getName();
    cx.meta.grid_class = GridClass::kLevelSet;
    cx.meta.has_normal = true;
    Status s = IngestGrid(*layout, layout->grids[0], /*double_values=*/false, cx);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(store_.finished);
    EXPECT_EQ(stats_.leaf_nodes, g->tree().leafCount());

    // OpenVDB's answer: every active voxel with value <= 0, tiles expanded.
    std::map<Ijk, bool> want;
    for (auto it = g->cbeginValueOn(); it; ++it) {
      if (*it > 0.0f) continue;
      openvdb::CoordBBox b;
      it.getBoundingBox(b);
      for (auto c = b.begin(); c; ++c) want[Ijk{(*c).x(), (*c).y(), (*c).z()}] = true;
    }
    const auto got = store_.Voxels();
    ASSERT_EQ(got.size(), want.size());
    for (const auto& [ijk, attr] : got) ASSERT_TRUE(want.count(ijk)) << ijk[0] << "," << ijk[1];
    EXPECT_EQ(stats_.occupied_voxels, want.size());

    // Bricks arrive in Morton order of their coordinates (the store's
    // records lie in that order: neighbours in space, neighbours in the
    // file), up to the bricks the parallel stage has in flight at once.
    std::vector<uint64_t> keys;
    for (const Ijk& c : store_.add_order)
      keys.push_back(MortonKey21(uint64_t(c[0]), uint64_t(c[1]), uint64_t(c[2])));
    std::vector<uint64_t> sorted = keys;
    std::sort(sorted.begin(), sorted.end());
    const long in_flight = 2 * std::max(2L, long(std::thread::hardware_concurrency()));
    for (size_t i = 0; i < keys.size(); ++i) {
      const long rank = long(std::lower_bound(sorted.begin(), sorted.end(), keys[i]) - sorted.begin());
      ASSERT_LE(std::labs(rank - long(i)), in_flight) << "brick added " << i << "th has Morton rank " << rank;
    }

    // Each brick's voxels strictly in Morton order.
    for (const auto& [bc, voxels] : store_.bricks)
      for (size_t i = 1; i < voxels.size(); ++i) {
        LeafPoint a{voxels[i - 1].x, voxels[i - 1].y, voxels[i - 1].z, 0};
        LeafPoint b{voxels[i].x, voxels[i].y, voxels[i].z, 0};
        ASSERT_TRUE(MortonLess(a, b)) << "brick " << bc[0] << "," << bc[1] << "," << bc[2]
                                      << " voxel " << i;
      }
  }

  testutil::TempDir dir_;
  testutil::FakeStore store_;
  IngestStats stats_;
};

TEST_F(GridIngestTest, LeafBricksAreOpenVdbsVoxelsInMortonOrder) {
  auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(14.0f, openvdb::Vec3f(-3, 5, 2),
                                                                    1.0f, 3.0f);
  g->setName("sphere");
  for (const char* levels : {"auto", "3+3", "4+2", "5+1"}) Run(g, levels);
}

TEST_F(GridIngestTest, TilesAndLeavesShareBricks) {
  auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(10.0f, openvdb::Vec3f(0.0f),
                                                                    1.0f, 3.0f);
  g->setName("mixed");
  g->tree().addTile(1, Coord(16, 0, 0), -1.0f, true);   // occupied tile beside the band
  g->tree().addTile(1, Coord(24, 8, 0), 2.0f, true);    // active but not occupied
  g->tree().addTile(1, Coord(-24, -8, 8), -3.0f, true);  // another, across the origin
  for (const char* levels : {"auto", "6+4", "8+3"}) Run(g, levels);
  EXPECT_EQ(stats_.occupied_tile_voxels, 2u * 512u);
}

}  // namespace
}  // namespace vox

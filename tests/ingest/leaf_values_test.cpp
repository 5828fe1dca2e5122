// The private leaf-value reader (ingest/internal/leaf_values.h): on a file
// read with delayed loading, every value read through PrivateReader and
// LeafValues equals OpenVDB's own value from the grid held in memory, and no
// leaf buffer of the file's tree gets loaded.
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/internal/leaf_values.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::LeafValues;
using ingest_internal::PrivateReader;
using openvdb::Coord;

class LeafValuesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  void SetUp() override {
    // Leaves (a sphere's narrow band), an active tile and inactive background.
    truth_ = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        10.0f, openvdb::Vec3f(2, -3, 1),
                                                                      1.0f, 3.0f);
    truth_->setName("ls");
    truth_->tree().addTile(1, Coord(64, 0, 0), -0.75f, true);  // an 8^3 tile
    path_ = dir_.File("grid.vdb");
    testutil::WriteVdb(path_, {truth_});
    file_ = std::make_unique<openvdb::io::File>(path_);
    file_->setCopyMaxBytes(0);
    file_->open(/*delayLoad=*/true);
    loaded_ = openvdb::gridPtrCast<openvdb::FloatGrid>(file_->readGrid("ls"));
    ASSERT_TRUE(loaded_);
  }

  // Leaves of the file's tree whose buffers are in memory.
  uint64_t ResidentLeaves() const {
    uint64_t n = 0;
    for (auto it = loaded_->constTree().cbeginLeaf(); it; ++it)
      if (!it->buffer().isOutOfCore()) ++n;
    return n;
  }

  testutil::TempDir dir_;
  std::string path_;
  openvdb::FloatGrid::Ptr truth_, loaded_;
  std::unique_ptr<openvdb::io::File> file_;
};

TEST_F(LeafValuesTest, ValuesMatchOpenVdbAndLeavesStayOnDisk) {
  ASSERT_EQ(ResidentLeaves(), 0u) << "delayed loading is off";
  PrivateReader<openvdb::FloatGrid> reader(*loaded_);
  auto acc = truth_->getConstAccessor();
  uint64_t compared = 0;
  // Every voxel of a box holding leaves, the tile and background.
  for (int x = -16; x <= 80; ++x)
    for (int y = -16; y <= 12; ++y)
      for (int z = -14; z <= 12; z += 3) {
        const Coord c(x, y, z);
        ASSERT_EQ(reader.Value(c), acc.getValue(c)) << c;
        ++compared;
      }
  EXPECT_GT(compared, 10000u);
  EXPECT_EQ(reader.Value(Coord(70, 3, 5)), -0.75f);  // inside the tile
  reader.Clear();
  EXPECT_EQ(reader.Value(Coord(12, -3, 1)), acc.getValue(Coord(12, -3, 1)));
  EXPECT_EQ(ResidentLeaves(), 0u) << "a read loaded a leaf into the tree";
}

TEST_F(LeafValuesTest, LeafCopiesHoldEveryValueOfTheLeaf) {
  LeafValues<openvdb::FloatTree::LeafNodeType> values;
  uint64_t leaves = 0;
  for (auto it = loaded_->constTree().cbeginLeaf(); it; ++it, ++leaves) {
    const float* d = values.Get(it.getLeaf());
    ASSERT_EQ(values.Get(it.getLeaf()), d) << "decoded twice";
    const auto* twin = truth_->constTree().probeConstLeaf(it->origin());
    ASSERT_NE(twin, nullptr);
    for (openvdb::Index n = 0; n < openvdb::FloatTree::LeafNodeType::SIZE; ++n)
      ASSERT_EQ(d[n], twin->getValue(n)) << it->origin() << " offset " << n;
    if (leaves % 16 == 15) values.Clear();
  }
  EXPECT_EQ(leaves, truth_->tree().leafCount());
  EXPECT_EQ(ResidentLeaves(), 0u);
}

TEST_F(LeafValuesTest, InMemoryTreesAreReadInPlace) {
  // Without delayed loading the leaf's own buffer is used, not a copy.
  LeafValues<openvdb::FloatTree::LeafNodeType> values;
  const auto* leaf = truth_->constTree().cbeginLeaf().getLeaf();
  EXPECT_EQ(values.Get(leaf), leaf->buffer().data());
}

}  // namespace
}  // namespace vox

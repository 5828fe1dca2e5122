// The coordinate convention and the values vox reads out of a store, against
// OpenVDB's own answers for the same grids: vox-probe's hits against the
// openvdb::Coord that holds each point.
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include "ingest/ingest.h"
#include "storage/store.h"
#include "tests/common/run_command.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using openvdb::Coord;
using testutil::TempDir;

class ValuesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  // Ingests `grid` (written to a .vdb first) into a store; returns its path.
  std::string IngestGrid(openvdb::GridBase::Ptr grid, const std::string& name) {
    const std::string vdb = dir_.File(name + ".vdb");
    testutil::WriteVdb(vdb, {grid});
    IngestOptions o;
    o.input = vdb;
    o.output = dir_.File(name + ".store");
    o.threads = 1;
    auto st = Ingest(o);
    EXPECT_TRUE(st.ok()) << st.status().ToString();
    return o.output;
  }

  TempDir dir_;
};

// A fog volume: a one-voxel wall at x = 5 over j, k in [-3, 3], plus a
// checker of voxels along y = -1 .. 1 so that a point half a voxel off
// lands in a voxel of another density.
openvdb::FloatGrid::Ptr Wall() {
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  g->setName("density");
  auto acc = g->getAccessor();
  for (int j = -3; j <= 3; ++j)
    for (int k = -3; k <= 3; ++k) acc.setValue(Coord(5, j, k), 0.25f + 0.1f * float(j + 3) + 0.01f * float(k + 3));
  return g;
}

// Rays along +x at heights crossing OpenVDB's voxel boundary at -0.5 and
// vox's at 0: vox-probe takes points in its index space, where voxel ijk is
// [ijk, ijk + 1)^3, so OpenVDB's index point q is vox's q + 0.5; the voxel
// it reports is the openvdb::Coord that holds q (Coord::round).
TEST_F(ValuesTest, ProbeReportsTheOpenVdbCoordOfEachPoint) {
  auto grid = Wall();
  const std::string store = IngestGrid(grid, "wall");
  const std::vector<double> heights = {-1.2, -0.7, -0.5001, -0.5, -0.4999, -0.2, -1e-9, 0.0, 1e-9, 0.2, 0.4999, 0.5, 0.7};
  std::ostringstream rays;
  rays.precision(17);
  std::vector<Coord> expect;
  for (double y : heights)
    for (double z : heights) {
      const openvdb::Vec3d q(-10.0, y, z);  // OpenVDB index space
      rays << q.x() + 0.5 << ' ' << q.y() + 0.5 << ' ' << q.z() + 0.5 << " 1 0 0\n";
      // The first active voxel along the ray, as OpenVDB places points in voxels.
      Coord c = Coord::round(q);
      while (!grid->tree().isValueOn(c) && c.x() < 10) c = Coord::round(openvdb::Vec3d(c.x() + 1, y, z));
      expect.push_back(c);
    }
  const std::string rays_file = dir_.File("rays.txt");
  std::ofstream(rays_file) << rays.str();
  auto r = testing::RunCommand(std::string(VOX_PROBE_BIN) + " " + store + " < " + rays_file);
  ASSERT_EQ(r.code, 0) << r.output;
  std::istringstream out(r.output);
  for (const Coord& c : expect) {
    std::string word;
    int64_t i = 0, j = 0, k = 0;
    double t = 0;
    ASSERT_TRUE(out >> word >> i >> j >> k >> t) << r.output;
    EXPECT_EQ(word, "hit");
    EXPECT_EQ(Coord(int(i), int(j), int(k)), c);
  }
}

}  // namespace
}  // namespace vox

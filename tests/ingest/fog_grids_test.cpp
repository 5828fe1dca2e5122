// Several grids of one VDB in one store (format 1.3): a fog volume's density
// and a second float grid, its temperature, ingested together and read back
// against OpenVDB's own values (the grid's value where the transforms agree,
// openvdb::tools::BoxSampler where they do not); the refusals. And a store of
// format 1.2, written by the last vox-ingest writing 1.2 (checked in under
// tests/ingest/data/), opens and renders to the same pixels as the same ball
// ingested today.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <cmath>
#include <cstring>
#include <string>

#include "ingest/ingest.h"
#include "render/renderer.h"
#include "storage/store.h"
#include "storage/store_info.h"
#include "tests/ingest/ingest_test_util.h"
#include "tests/render/render_util.h"

namespace vox {
namespace {

using openvdb::Coord;
using testutil::ReadAll;
using testutil::TempDir;

// The fog ball of tests/ingest/data/README.md.
openvdb::FloatGrid::Ptr Ball() {
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setName("density");
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  g->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
  for (int x = -5; x <= 5; ++x)
    for (int y = -5; y <= 5; ++y)
      for (int z = -5; z <= 5; ++z) {
        const double r = std::sqrt(double(x * x + y * y + z * z));
        if (r < 5.5) g->tree().setValue(Coord(x, y, z), float(1.0 - r / 6.0));
      }
  return g;
}

// A temperature varying on every axis, over a box larger than the ball.
openvdb::FloatGrid::Ptr Temperature(double voxel_size) {
  auto g = openvdb::FloatGrid::create(300.0f);
  g->setName("temperature");
  g->setTransform(openvdb::math::Transform::createLinearTransform(voxel_size));
  for (int x = -8; x <= 8; ++x)
    for (int y = -8; y <= 8; ++y)
      for (int z = -8; z <= 8; ++z)
        g->tree().setValue(Coord(x, y, z), float(1500.0 + 37.5 * x + 3.25 * y - 11.0 * z));
  return g;
}

class FogGridsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  StatusOr<std::unique_ptr<Store>> IngestAndOpen(const std::string& vdb, IngestOptions o) {
    o.input = vdb;
    o.output = dir_.File("store" + std::to_string(++count_));
    last_ = o.output;
    VOX_RETURN_IF_ERROR(Ingest(o).status());
    return Store::Open(o.output, OpenOptions{});
  }

  TempDir dir_;
  int count_ = 0;
  std::string last_;  // the last store ingested
};

TEST_F(FogGridsTest, TemperatureIsOpenVdbsValueAtEachVoxel) {
  for (double voxel : {0.25, 0.4}) {  // the density's transform, and another
    SCOPED_TRACE("temperature voxel size " + std::to_string(voxel));
    auto ball = Ball();
    auto temp = Temperature(voxel);
    const std::string vdb = dir_.File("fire" + std::to_string(count_) + ".vdb");
    testutil::WriteVdb(vdb, {ball, temp});
    IngestOptions o;
    o.grid_name = "density";
    o.temperature_grid = "temperature";
    auto store = IngestAndOpen(vdb, o);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    const StoreMeta& m = (*store)->meta();
    EXPECT_TRUE(m.has_temperature);
    EXPECT_TRUE(m.has_density);
    auto all = ReadAll(**store);
    ASSERT_TRUE(all.ok());
    ASSERT_GT(all->size(), 400u);
    auto dacc = ball->getConstAccessor();
    auto tacc = temp->getConstAccessor();
    openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler>
        sampler(tacc, temp->transform());
    for (const auto& [g, sv] : *all) {
      const Coord ijk(int(g[0] + m.origin.x), int(g[1] + m.origin.y), int(g[2] + m.origin.z));
      auto a = (*store)->Attributes(sv.brick, sv.payload);
      ASSERT_TRUE(a.ok());
      EXPECT_EQ(a->density, dacc.getValue(ijk));
      if (voxel == 0.25)
        EXPECT_EQ(a->temperature, tacc.getValue(ijk)) << ijk;
      else
        EXPECT_NEAR(a->temperature, sampler.wsSample(ball->transform().indexToWorld(ijk)), 1e-3)
            << ijk;
    }
    auto info = InspectStore(last_, false);
    ASSERT_TRUE(info.ok());
    EXPECT_EQ(info->format_minor, 3);
    EXPECT_NE(FormatStoreInfo(*info).find("temperature"), std::string::npos);
  }
}

TEST_F(FogGridsTest, RefusesATemperatureGridItCannotUse) {
  auto ball = Ball();
  auto rgb = openvdb::Vec3fGrid::create();
  rgb->setName("rgb");
  rgb->tree().setValue(Coord(0, 0, 0), openvdb::Vec3f(1.0f));
  const std::string vdb = dir_.File("bad.vdb");
  testutil::WriteVdb(vdb, {ball, rgb});
  struct Case {
    std::string grid, want;
  } cases[] = {{"heat", "no temperature grid named 'heat'"},
               {"rgb", "holds vec3s values"},
               {"density", "is the grid being ingested"}};
  for (const Case& c : cases) {
    IngestOptions o;
    o.temperature_grid = c.grid;
    auto s = IngestAndOpen(vdb, o);
    ASSERT_FALSE(s.ok()) << c.grid;
    EXPECT_NE(s.status().message().find(c.want), std::string::npos) << s.status().ToString();
    EXPECT_NE(s.status().message().find(vdb), std::string::npos) << s.status().ToString();
  }
}

// The same fog ball through the format 1.2 store of tests/ingest/data and
// through a store ingested now (format 1.3): the same voxels, the same
// pixels.
TEST_F(FogGridsTest, Format12StoreOpensAndRendersAsToday) {
  const std::string old_dir = std::string(VOX_TEST_DATA_DIR) + "/fog_ball_1.2";
  auto info = InspectStore(old_dir, /*verify_bricks=*/true);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->format_major, 1);
  EXPECT_EQ(info->format_minor, 2);
  auto old_store = Store::Open(old_dir, OpenOptions{});
  ASSERT_TRUE(old_store.ok()) << old_store.status().ToString();
  EXPECT_FALSE((*old_store)->meta().has_temperature);

  const std::string vdb = dir_.File("ball.vdb");
  testutil::WriteVdb(vdb, {Ball()});
  IngestOptions o;
  o.lod = false;
  auto new_store = IngestAndOpen(vdb, o);
  ASSERT_TRUE(new_store.ok()) << new_store.status().ToString();
  EXPECT_EQ((*new_store)->meta().voxel_count, (*old_store)->meta().voxel_count);

  Camera cam;
  cam.position = glm::dvec3(2.0, 1.5, 3.0);
  cam.look_at = glm::dvec3(0.0);
  cam.fov_deg = 40;
  cam.width = 48;
  cam.height = 40;
  ASSERT_TRUE(cam.Finalize().ok());
  auto scene = ParseScene(
      R"({"lights":[{"type":"directional","direction":[-0.3,-1,-0.5]}],
          "volume":{"absorption":2,"scattering":[3,2,1],"phase_g":0.3}})",
      "scene.json");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  testing::Image img[2];
  Store* stores[2] = {old_store->get(), new_store->get()};
  for (int i = 0; i < 2; ++i) {
    auto r = Renderer::Create(stores[i], cam, *scene, RenderOptions{});
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    RenderCounters c;
    ASSERT_TRUE(testing::RenderToMemory(**r, &img[i], &c).ok());
  }
  EXPECT_GT(img[0].at("A", 24, 20), 0.3f);
  EXPECT_GT(img[0].at("R", 24, 20), 0.01f);
  for (const auto& [name, px] : img[0].ch)
    EXPECT_EQ(std::memcmp(px.data(), img[1].ch.at(name).data(), px.size() * sizeof(float)), 0)
        << name;

  // A scene asking for blackbody emission is refused on a store without temperatures.
  auto hot = ParseScene(R"({"volume":{"blackbody":{"intensity":1}}})", "hot.json");
  ASSERT_TRUE(hot.ok());
  auto r = Renderer::Create(old_store->get(), cam, *hot, RenderOptions{});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("--temperature"), std::string::npos) << r.status().ToString();
}

}  // namespace
}  // namespace vox

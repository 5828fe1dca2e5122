// Ingest into real stores: VDBs built here, ingested with the StoreWriter,
// opened with Store::Open and read back whole (every brick walked), compared
// with the source grid; first hits of random rays over the store, at several
// splits, checked against the exact reference of the core tests. Also the
// atomicity of failed ingests.
#include <sys/stat.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetPlatonic.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include "core/tracer.h"
#include "ingest/ingest.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/core/test_util.h"
#include "tests/ingest/ingest_test_util.h"
#include "tests/study/reference.h"

namespace vox {
namespace {

using openvdb::Coord;
using testutil::Ijk;
using testutil::ReadAll;
using testutil::TempDir;

template <class GridT>
std::map<Ijk, double> SourceOccupied(const GridT& grid, bool level_set, double cut) {
  std::map<Ijk, double> out;
  for (auto it = grid.cbeginValueOn(); it; ++it) {
    double v = double(*it);
    if (level_set ? !(v <= cut) : !(v > cut)) continue;
    openvdb::CoordBBox b;
    it.getBoundingBox(b);
    for (auto c = b.begin(); c; ++c) out[Ijk{(*c).x(), (*c).y(), (*c).z()}] = v;
  }
  return out;
}

class IngestStoreTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  std::unique_ptr<Store> IngestAndOpen(const std::string& vdb, IngestOptions o = {}) {
    o.input = vdb;
    o.output = dir_.File("store" + std::to_string(++count_));
    auto st = Ingest(o);
    EXPECT_TRUE(st.ok()) << st.status().ToString();
    if (!st.ok()) return nullptr;
    auto store = Store::Open(o.output, OpenOptions{});
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(store).value() : nullptr;
  }

  // Store contents == source occupancy; attributes within quantisation.
  template <class GridT>
  void ExpectStoreMatches(Store& store, const GridT& grid, bool level_set, double cut) {
    const StoreMeta& m = store.meta();
    auto src = SourceOccupied(grid, level_set, cut);
    auto got = ReadAll(store);
    ASSERT_TRUE(got.ok()) << got.status().ToString();
    ASSERT_EQ(got->size(), src.size());
    EXPECT_EQ(m.voxel_count, src.size());
    auto acc = grid.getConstAccessor();
    for (const auto& [g, sv] : *got) {
      Ijk ijk{g[0] + m.origin.x, g[1] + m.origin.y, g[2] + m.origin.z};
      auto it = src.find(ijk);
      ASSERT_NE(it, src.end()) << "store voxel " << ijk[0] << "," << ijk[1] << "," << ijk[2]
                               << " is not occupied in the source";
      auto attr = store.Attributes(sv.brick, sv.payload);
      ASSERT_TRUE(attr.ok()) << attr.status().ToString();
      if (level_set) {
        auto gr = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(
            acc, Coord(int(ijk[0]), int(ijk[1]), int(ijk[2])));
        if (gr.length() > 0) {
          gr.normalize();
          double dot = gr[0] * attr->normal.x + gr[1] * attr->normal.y + gr[2] * attr->normal.z;
          ASSERT_GT(dot, 0.99999) << "normal at " << ijk[0] << "," << ijk[1] << "," << ijk[2];
        }
      } else {
        ASSERT_EQ(attr->density, float(it->second));
      }
    }
  }

  // First hits of rays over the store, at several splits, against the exact
  // reference built from the source's occupied voxels.
  void ExpectProbesExact(Store& store, const std::map<Ijk, double>& src, int rays) {
    const StoreMeta& m = store.meta();
    std::vector<testing::Voxel> voxels;
    for (const auto& [ijk, v] : src)
      voxels.push_back({ijk[0] - m.origin.x, ijk[1] - m.origin.y, ijk[2] - m.origin.z});
    testing::Reference ref(voxels, m.levels);
    testing::Rng rng(1234);
    std::vector<int> splits = {m.brick_level};
    for (int n1 = 1; n1 < m.levels; n1 += 2)
      if (n1 != m.brick_level) splits.push_back(n1);
    for (int n1 : splits) {
      auto tracer = DefaultTracer::Create(store.view(), n1);
      ASSERT_TRUE(tracer.ok()) << tracer.status().ToString();
      int failures = 0;
      for (int i = 0; i < rays; ++i) {
        // Aim at an occupied voxel half the time, elsewhere otherwise.
        glm::dvec3 target;
        if (i % 2 == 0 && !voxels.empty()) {
          target = rng.PointIn(voxels[size_t(rng.Int(0, int64_t(voxels.size()) - 1))]);
        } else {
          double g = std::ldexp(1.0, m.levels);
          target = {rng.Uniform(0, g), rng.Uniform(0, g), rng.Uniform(0, g)};
        }
        Ray ray = testing::RayFromOutside(rng, m.levels, target, std::ldexp(3.0, m.levels));
        testing::ExactRay exact(ray);
        testing::RefHit want = ref.FirstHit(exact);
        std::string why = testing::TraceAndCheck(*tracer, ref, exact, want);
        if (!why.empty() && ++failures <= 3) ADD_FAILURE() << "n1=" << n1 << ": " << why;
      }
      EXPECT_EQ(failures, 0) << "split " << n1 << "+" << m.levels - n1;
    }
  }

  TempDir dir_;
  int count_ = 0;
};

TEST_F(IngestStoreTest, SphereRoundTripAndProbes) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      18.0f, openvdb::Vec3f(-40.5f, 3.2f, -7.7f), 1.0f, 3.0f);
  grid->setName("sphere");
  std::string vdb = dir_.File("sphere.vdb");
  testutil::WriteVdb(vdb, {grid});
  auto store = IngestAndOpen(vdb);
  ASSERT_TRUE(store);
  const StoreMeta& m = store->meta();
  EXPECT_EQ(m.grid_name, "sphere");
  EXPECT_EQ(m.source_file, vdb);
  EXPECT_EQ(m.grid_class, GridClass::kLevelSet);
  EXPECT_TRUE(m.has_normal);
  EXPECT_EQ(m.levels - m.brick_level, 5);
  openvdb::Vec3d w = grid->transform().indexToWorld(Coord(3, -4, 5));
  glm::dvec4 mw = m.index_to_world * glm::dvec4(3, -4, 5, 1);
  EXPECT_NEAR(mw.x, w[0], 1e-12);
  EXPECT_NEAR(mw.y, w[1], 1e-12);
  EXPECT_NEAR(mw.z, w[2], 1e-12);
  ExpectStoreMatches(*store, *grid, true, 0.0);
  ExpectProbesExact(*store, SourceOccupied(*grid, true, 0.0), 300);
}

TEST_F(IngestStoreTest, PlatonicUnionWithSmallBricks) {
  auto a = openvdb::tools::createLevelSetPlatonic<openvdb::FloatGrid>(
      12, 20.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  auto b = openvdb::tools::createLevelSetPlatonic<openvdb::FloatGrid>(
      8, 16.0f, openvdb::Vec3f(14.0f, -6.0f, 3.0f), 1.0f, 3.0f);
  openvdb::tools::csgUnion(*a, *b);
  a->setName("union");
  std::string vdb = dir_.File("union.vdb");
  testutil::WriteVdb(vdb, {a});
  IngestOptions o;
  o.levels = "4+3";
  auto store = IngestAndOpen(vdb, o);
  ASSERT_TRUE(store);
  EXPECT_EQ(store->meta().brick_level, 4);
  EXPECT_EQ(store->meta().levels, 7);
  ExpectStoreMatches(*store, *a, true, 0.0);
  ExpectProbesExact(*store, SourceOccupied(*a, true, 0.0), 200);
}

TEST_F(IngestStoreTest, FogVolumeRotated) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      10.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  openvdb::tools::sdfToFogVolume(*grid);
  openvdb::math::Mat4d mat = openvdb::math::Mat4d::identity();
  mat.preScale(openvdb::Vec3d(0.5, 0.5, 0.5));
  mat.postRotate(openvdb::math::Y_AXIS, 0.7);
  mat.postTranslate(openvdb::Vec3d(1.0, 2.0, 3.0));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(mat));
  grid->setName("fog");
  std::string vdb = dir_.File("fog.vdb");
  testutil::WriteVdb(vdb, {grid});
  IngestOptions o;
  o.threshold = 0.25;
  auto store = IngestAndOpen(vdb, o);
  ASSERT_TRUE(store);
  EXPECT_EQ(store->meta().grid_class, GridClass::kFogVolume);
  EXPECT_TRUE(store->meta().has_density);
  EXPECT_DOUBLE_EQ(store->meta().threshold, 0.25);
  EXPECT_NEAR(store->meta().voxel_size, 0.5, 1e-12);
  ExpectStoreMatches(*store, *grid, false, 0.25);
  ExpectProbesExact(*store, SourceOccupied(*grid, false, 0.25), 200);
}

TEST_F(IngestStoreTest, SingleVoxelAndEmptyGrid) {
  auto one = openvdb::FloatGrid::create(3.0f);
  one->setGridClass(openvdb::GRID_LEVEL_SET);
  one->setName("one");
  one->tree().setValueOn(Coord(-77, 1000, -5), -0.5f);
  auto empty = openvdb::FloatGrid::create(3.0f);
  empty->setGridClass(openvdb::GRID_LEVEL_SET);
  empty->setName("empty");
  std::string vdb = dir_.File("small.vdb");
  testutil::WriteVdb(vdb, {one, empty});
  IngestOptions o;
  o.grid_name = "one";
  auto store = IngestAndOpen(vdb, o);
  ASSERT_TRUE(store);
  auto all = ReadAll(*store);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 1u);
  const StoreMeta& m = store->meta();
  Ijk g = all->begin()->first;
  EXPECT_EQ(g[0] + m.origin.x, -77);
  EXPECT_EQ(g[1] + m.origin.y, 1000);
  EXPECT_EQ(g[2] + m.origin.z, -5);
  ExpectProbesExact(*store, SourceOccupied(*one, true, 0.0), 100);

  o.grid_name = "empty";
  auto es = IngestAndOpen(vdb, o);
  ASSERT_TRUE(es);
  EXPECT_EQ(es->meta().voxel_count, 0u);
  EXPECT_EQ(es->meta().brick_count, 0u);
  auto none = ReadAll(*es);
  ASSERT_TRUE(none.ok()) << none.status().ToString();
  EXPECT_TRUE(none->empty());
  auto tracer = DefaultTracer::Create(es->view(), es->meta().brick_level);
  ASSERT_TRUE(tracer.ok());
  Ray r;
  r.origin = {-5.0, 1.5, 2.5};
  r.dir = {1.0, 0.01, 0.02};
  auto hit = tracer->FirstHit(r);
  ASSERT_TRUE(hit.ok());
  EXPECT_FALSE(hit->has_value());
}

TEST_F(IngestStoreTest, ColorsStored) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      6.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  grid->setName("shape");
  auto rgb = openvdb::Vec3fGrid::create(openvdb::Vec3f(0.0f));
  rgb->setName("rgb");
  for (auto it = grid->cbeginValueOn(); it; ++it) {
    Coord c = it.getCoord();
    rgb->tree().setValueOn(c, openvdb::Vec3f(0.5f + c.x() * 0.01f, 0.25f, 1.0f - c.z() * 0.01f));
  }
  std::string vdb = dir_.File("color.vdb");
  testutil::WriteVdb(vdb, {grid, rgb});
  IngestOptions o;
  o.color_grid = "rgb";
  auto store = IngestAndOpen(vdb, o);
  ASSERT_TRUE(store);
  EXPECT_TRUE(store->meta().has_color);
  auto all = ReadAll(*store);
  ASSERT_TRUE(all.ok());
  ASSERT_FALSE(all->empty());
  const StoreMeta& m = store->meta();
  for (const auto& [g, sv] : *all) {
    auto attr = store->Attributes(sv.brick, sv.payload);
    ASSERT_TRUE(attr.ok());
    int64_t x = g[0] + m.origin.x, z = g[2] + m.origin.z;
    EXPECT_NEAR(attr->color.r, 0.5f + x * 0.01f, 1e-3);
    EXPECT_NEAR(attr->color.g, 0.25f, 1e-3);
    EXPECT_NEAR(attr->color.b, 1.0f - z * 0.01f, 1e-3);
  }
}

// The pyramid the ingest builds with the bricks is, byte for byte, the one
// BuildLod (as `vox-ingest --add-lod` runs it) writes of the finished store:
// a level set with an occupied active tile (whose voxels the surface test of
// neighbouring bricks looks up) and a fog volume (interior tiles), bricks of
// 4^3 (most voxels' neighbours in another brick) and of 2^5, 1 and 2 threads.
TEST_F(IngestStoreTest, ThePyramidBuiltWithTheBricksIsBuildLods) {
  auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      20.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  ls->tree().addTile(1, Coord(16, 0, 0), -1.0f, true);  // an 8^3 tile on the surface
  ls->setName("ls");
  auto fog = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      20.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  openvdb::tools::sdfToFogVolume(*fog);
  fog->setName("fog");
  const std::string ls_vdb = dir_.File("ls.vdb"), fog_vdb = dir_.File("fog.vdb");
  testutil::WriteVdb(ls_vdb, {ls});
  testutil::WriteVdb(fog_vdb, {fog});
  auto files = [](const std::string& store) {
    std::map<std::string, std::string> bytes;
    for (const auto& e : std::filesystem::recursive_directory_iterator(store + "/lod"))
      if (e.is_regular_file()) {
        std::ifstream f(e.path(), std::ios::binary);
        bytes[std::filesystem::relative(e.path(), store).string()] =
            std::string(std::istreambuf_iterator<char>(f), {});
      }
    return bytes;
  };
  int n = 0;
  for (const std::string& vdb : {ls_vdb, fog_vdb})
    for (const char* levels : {"5+2", "auto"})
      for (int threads : {1, 2}) {
        SCOPED_TRACE(vdb + " " + levels + " threads " + std::to_string(threads));
        IngestOptions o;
        o.input = vdb;
        o.output = dir_.File("lod" + std::to_string(n++));
        o.levels = levels;
        o.threads = threads;
        auto st = Ingest(o);
        ASSERT_TRUE(st.ok()) << st.status().ToString();
        ASSERT_GT(st->lod_levels, 2);
        if (vdb == ls_vdb) {
          EXPECT_GT(st->occupied_tile_voxels, 0u);
        }
        const auto streamed = files(o.output);
        ASSERT_EQ(streamed.size(), 2u * size_t(st->lod_levels));
        LodBuildOptions lo;
        lo.force = true;
        ASSERT_TRUE(BuildLod(o.output, lo).ok());
        for (const auto& [name, bytes] : files(o.output))
          EXPECT_TRUE(streamed.at(name) == bytes) << name << " differs";
      }
}

// A StoreWriter that passes bricks to the real writer and fails on demand.
class FailingWriter : public StoreWriter {
 public:
  FailingWriter(std::unique_ptr<StoreWriter> inner, int fail_at)
      : inner_(std::move(inner)), fail_at_(fail_at) {}
  Status AddBrick(const glm::u64vec3& c, std::vector<BrickVoxel> v) override {
    if (count_.fetch_add(1) == fail_at_) return IoError("/fake: No space left on device");
    return inner_->AddBrick(c, std::move(v));
  }
  Status Finish() override { return inner_->Finish(); }

 private:
  std::unique_ptr<StoreWriter> inner_;
  int fail_at_;
  std::atomic<int> count_{0};
};

TEST_F(IngestStoreTest, FailedIngestLeavesNoStore) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      25.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  std::string vdb = dir_.File("s.vdb");
  testutil::WriteVdb(vdb, {grid});
  for (int fail_at : {0, 3}) {
    IngestOptions o;
    o.input = vdb;
    o.output = dir_.File("failed" + std::to_string(fail_at));
    auto factory = [&](const std::string& d, const StoreMeta& m,
                       const WriteOptions& w) -> StatusOr<std::unique_ptr<StoreWriter>> {
      auto inner = StoreWriter::Create(d, m, w);
      if (!inner.ok()) return inner.status();
      return std::unique_ptr<StoreWriter>(new FailingWriter(std::move(inner).value(), fail_at));
    };
    auto st = IngestWithWriter(o, factory);
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.status().message().find("No space left"), std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(o.output));
    EXPECT_FALSE(Store::Open(o.output, OpenOptions{}).ok());
    // Nothing left beside the target either (the temporary directory is gone).
    for (const auto& e : std::filesystem::directory_iterator(dir_.path()))
      EXPECT_EQ(e.path().filename().string().find("failed"), std::string::npos)
          << e.path() << " left behind";
  }
  // A bad grid after a good one: the earlier store stays, no new one appears.
  IngestOptions o;
  o.input = vdb;
  o.output = dir_.File("good");
  ASSERT_TRUE(Ingest(o).ok());
  o.force = true;
  o.grid_name = "missing";
  EXPECT_FALSE(Ingest(o).ok());
  EXPECT_TRUE(Store::Open(o.output, OpenOptions{}).ok());
}

// A cancel while the level-of-detail pyramid is built (the pyramid's bricks
// are the ingest's last progress points) stops the ingest: --force or not,
// the old store stays, byte for byte, and nothing is left beside it.
TEST_F(IngestStoreTest, CancelDuringThePyramidKeepsTheOldStore) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      40.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  const std::string vdb = dir_.File("s.vdb");
  testutil::WriteVdb(vdb, {grid});
  IngestOptions o;
  o.input = vdb;
  o.output = dir_.File("store");
  o.levels = "5+2";  // small bricks: many pyramid progress points
  ASSERT_TRUE(Ingest(o).ok());
  auto snapshot = [&] {
    std::map<std::string, std::string> files;
    for (const auto& e : std::filesystem::recursive_directory_iterator(o.output))
      if (e.is_regular_file()) {
        std::ifstream f(e.path(), std::ios::binary);
        files[e.path().string()] = std::string(std::istreambuf_iterator<char>(f), {});
      }
    return files;
  };
  const auto before = snapshot();
  ASSERT_TRUE(before.count(o.output + "/lod/1/bricks.vxb"));

  // Cancelled once the pyramid has begun: after `polls` more questions.
  class CancelInPyramid : public ProgressSink {
   public:
    explicit CancelInPyramid(int polls) : polls_(polls) {}
    void Message(std::string_view line) override {
      if (line.find("level-of-detail") != std::string_view::npos) in_pyramid_ = true;
    }
    void Progress(uint64_t, uint64_t, uint64_t) override {}
    void Done() override {}
    bool Cancelled() override { return in_pyramid_ && polls_-- <= 0; }
    bool in_pyramid_ = false;

   private:
    int polls_;
  };
  o.force = true;
  for (int polls : {0, 5}) {
    CancelInPyramid sink(polls);
    auto st = Ingest(o, &sink);
    ASSERT_TRUE(sink.in_pyramid_);
    ASSERT_FALSE(st.ok()) << "polls " << polls;
    EXPECT_NE(st.status().message().find("cancelled"), std::string::npos) << st.status().ToString();
    EXPECT_EQ(snapshot(), before) << "polls " << polls;
    size_t entries = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir_.path())) {
      ++entries;
      EXPECT_TRUE(e.path().filename() == "s.vdb" || e.path().filename() == "store") << e.path();
    }
    EXPECT_EQ(entries, 2u);
  }
}

TEST_F(IngestStoreTest, ExistingAndUnwritableTargets) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      5.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  std::string vdb = dir_.File("s.vdb");
  testutil::WriteVdb(vdb, {grid});
  IngestOptions o;
  o.input = vdb;
  o.output = dir_.File("store");
  ASSERT_TRUE(Ingest(o).ok());
  auto again = Ingest(o);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.status().message().find("--force"), std::string::npos);
  o.force = true;
  EXPECT_TRUE(Ingest(o).ok()) << "--force replaces";
  EXPECT_TRUE(Store::Open(o.output, OpenOptions{}).ok());
  // A target under a regular file, and one in a missing directory.
  o.force = false;
  o.output = vdb + "/store";
  auto bad = Ingest(o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find(vdb), std::string::npos) << bad.status().ToString();
  o.output = dir_.File("no/such/dir/store");
  bad = Ingest(o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("no/such/dir"), std::string::npos)
      << bad.status().ToString();
}

}  // namespace
}  // namespace vox

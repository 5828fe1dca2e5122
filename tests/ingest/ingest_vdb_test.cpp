// Ingest tests against a recording StoreWriter: VDBs built here with
// OpenVDB, ingested, and the bricks handed to the writer compared with the
// source grid voxel by voxel (set equality, normals, densities, colours,
// metadata). Also the placement rules and every bad input.
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetPlatonic.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include "ingest/ingest.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using openvdb::Coord;
using testutil::FakeStore;
using testutil::Ijk;
using testutil::TempDir;

// Runs the ingest of `grid_name` in `path` into a FakeStore.
struct FakeRun {
  StatusOr<IngestStats> stats = InternalError("not run");
  FakeStore store;
};

FakeRun RunFake(IngestOptions o) {
  FakeRun r;
  if (o.output.empty()) o.output = "/nonexistent-target-for-fake";
  r.stats = IngestWithWriter(o, r.store.Factory());
  return r;
}

IngestOptions Opts(const std::string& input, const std::string& grid = "") {
  IngestOptions o;
  o.input = input;
  o.grid_name = grid;
  return o;
}

// Source occupancy from OpenVDB's own active-value iteration, tiles expanded.
template <class GridT>
std::map<Ijk, double> SourceOccupied(const GridT& grid, bool level_set, double cut) {
  std::map<Ijk, double> out;
  for (auto it = grid.cbeginValueOn(); it; ++it) {
    double v = double(*it);
    bool occ = level_set ? v <= cut : v > cut;
    if (!occ) continue;
    openvdb::CoordBBox b;
    it.getBoundingBox(b);
    for (auto c = b.begin(); c; ++c) out[Ijk{(*c).x(), (*c).y(), (*c).z()}] = v;
  }
  return out;
}

template <class GridT>
void ExpectSameVoxels(const FakeStore& store, const GridT& grid, bool level_set, double cut) {
  auto src = SourceOccupied(grid, level_set, cut);
  auto got = store.Voxels();
  ASSERT_EQ(got.size(), src.size());
  size_t mismatches = 0;
  for (const auto& [ijk, v] : src)
    if (!got.count(ijk) && ++mismatches < 5)
      ADD_FAILURE() << "missing voxel " << ijk[0] << "," << ijk[1] << "," << ijk[2];
  EXPECT_EQ(mismatches, 0u);
  // Bounding box: exactly the occupied voxels'.
  if (!src.empty()) {
    Ijk lo = src.begin()->first, hi = lo;
    for (const auto& [ijk, v] : src)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], ijk[a]);
        hi[a] = std::max(hi[a], ijk[a]);
      }
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(store.meta.bbox_min[a], lo[a]);
      EXPECT_EQ(store.meta.bbox_max[a], hi[a]);
    }
  }
}

// Normals equal OpenVDB's index-space central-difference gradient, normalised.
template <class GridT>
void ExpectNormals(const FakeStore& store, const GridT& grid) {
  auto acc = grid.getConstAccessor();
  size_t bad = 0;
  for (const auto& [ijk, attr] : store.Voxels()) {
    auto g = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc,
                                                                       Coord(ijk[0], ijk[1], ijk[2]));
    double len = g.length();
    glm::dvec3 want = len > 0 ? glm::dvec3(g[0] / len, g[1] / len, g[2] / len) : glm::dvec3(0.0);
    glm::dvec3 got(attr.normal);
    if (glm::length(got - want) > 1e-5 && ++bad < 5)
      ADD_FAILURE() << "normal at " << ijk[0] << "," << ijk[1] << "," << ijk[2] << ": got "
                    << got.x << "," << got.y << "," << got.z << " want " << want.x << ","
                    << want.y << "," << want.z;
  }
  EXPECT_EQ(bad, 0u);
}

void ExpectPlacement(const FakeStore& store) {
  const StoreMeta& m = store.meta;
  const int b = m.levels - m.brick_level;
  ASSERT_GE(m.brick_level, 1);
  ASSERT_GE(b, 1);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(m.origin[a] % (int64_t(1) << b), 0) << "origin aligned to the brick size";
    if (m.bbox_min[a] <= m.bbox_max[a]) {
      EXPECT_EQ(m.origin[a], (m.bbox_min[a] >> b) << b);
      EXPECT_LT(m.bbox_max[a] - m.origin[a], int64_t(1) << m.levels);
    }
  }
  if (m.bbox_min[0] <= m.bbox_max[0] && m.levels > b + 1) {
    // Minimal: one level less would not cover the bbox.
    int64_t need = 0;
    for (int a = 0; a < 3; ++a) need = std::max<int64_t>(need, m.bbox_max[a] - m.origin[a] + 1);
    EXPECT_GT(need, int64_t(1) << (m.levels - 1));
  }
}

template <class GridT>
void ExpectTransform(const StoreMeta& m, const GridT& grid) {
  for (Coord c : {Coord(0, 0, 0), Coord(5, -7, 11), Coord(-100, 30, 2)}) {
    openvdb::Vec3d w = grid.transform().indexToWorld(c);
    glm::dvec4 got = m.index_to_world * glm::dvec4(c.x(), c.y(), c.z(), 1.0);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(got[a], w[a], 1e-9 * (1 + std::fabs(w[a])));
  }
  openvdb::Vec3d vs = grid.transform().voxelSize();
  EXPECT_DOUBLE_EQ(m.voxel_size, std::max({vs[0], vs[1], vs[2]}));
}

class IngestTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
  TempDir dir_;
};

TEST_F(IngestTest, SphereWithNegativeCoordinates) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      20.0f, openvdb::Vec3f(-33.3f, 5.1f, -70.7f), 1.0f, 3.0f);
  grid->setName("sphere");
  std::string path = dir_.File("sphere.vdb");
  testutil::WriteVdb(path, {grid});
  auto r = RunFake(Opts(path, "sphere"));
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  EXPECT_TRUE(r.store.finished);
  ExpectSameVoxels(r.store, *grid, true, 0.0);
  ExpectNormals(r.store, *grid);
  ExpectPlacement(r.store);
  ExpectTransform(r.store.meta, *grid);
  const StoreMeta& m = r.store.meta;
  EXPECT_EQ(m.grid_class, GridClass::kLevelSet);
  EXPECT_TRUE(m.has_normal);
  EXPECT_FALSE(m.has_density);
  EXPECT_FALSE(m.has_color);
  EXPECT_EQ(m.grid_name, "sphere");
  EXPECT_EQ(m.source_file, path);
  EXPECT_EQ(m.levels - m.brick_level, 5);  // auto: 32^3 bricks
  EXPECT_EQ(r.stats->occupied_voxels, r.store.Voxels().size());
  EXPECT_EQ(r.stats->active_voxels, grid->activeVoxelCount());
  EXPECT_EQ(r.stats->bricks, r.store.bricks.size());
  EXPECT_GT(r.stats->topology_bytes, 0u);
  EXPECT_LT(r.stats->topology_bytes, r.stats->leaf_nodes * 64 + (1u << 20))
      << "the topology is not compact";
  EXPECT_GT(r.stats->leaf_nodes, 0u);
}

TEST_F(IngestTest, PlatonicSolids) {
  for (int faces : {4, 6, 8, 12, 20}) {
    SCOPED_TRACE("faces " + std::to_string(faces));
    auto grid = openvdb::tools::createLevelSetPlatonic<openvdb::FloatGrid>(
        faces, 24.0f, openvdb::Vec3f(3.0f, -4.0f, 10.0f), 1.0f, 3.0f);
    grid->setName("solid");
    std::string path = dir_.File("platonic" + std::to_string(faces) + ".vdb");
    testutil::WriteVdb(path, {grid});
    auto r = RunFake(Opts(path));
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    ExpectSameVoxels(r.store, *grid, true, 0.0);
    ExpectNormals(r.store, *grid);
    ExpectPlacement(r.store);
  }
}

TEST_F(IngestTest, CsgUnionAndIsovalue) {
  auto a = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      14.0f, openvdb::Vec3f(0.0f, 0.0f, 0.0f), 0.5f, 3.0f);
  auto b = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      10.0f, openvdb::Vec3f(12.0f, 3.0f, -2.0f), 0.5f, 3.0f);
  openvdb::tools::csgUnion(*a, *b);
  a->setName("union");
  std::string path = dir_.File("union.vdb");
  testutil::WriteVdb(path, {a});
  for (double iso : {0.0, 0.6, -0.4}) {
    SCOPED_TRACE("isovalue " + std::to_string(iso));
    IngestOptions o = Opts(path);
    if (iso != 0.0) o.isovalue = iso;
    auto r = RunFake(o);
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    ExpectSameVoxels(r.store, *a, true, iso);
    ExpectNormals(r.store, *a);
    EXPECT_DOUBLE_EQ(r.store.meta.isovalue, iso);
  }
}

TEST_F(IngestTest, DoubleGrid) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(
      9.0f, openvdb::Vec3f(-2.5f, 40.0f, 1.0f), 1.0f, 3.0f);
  grid->setName("d");
  std::string path = dir_.File("double.vdb");
  testutil::WriteVdb(path, {grid});
  auto r = RunFake(Opts(path));
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  ExpectSameVoxels(r.store, *grid, true, 0.0);
  ExpectNormals(r.store, *grid);
}

TEST_F(IngestTest, FogVolumeDensities) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      12.0f, openvdb::Vec3f(-5.0f, -6.0f, -7.0f), 1.0f, 3.0f);
  openvdb::tools::sdfToFogVolume(*grid);
  grid->setName("fog");
  ASSERT_EQ(grid->getGridClass(), openvdb::GRID_FOG_VOLUME);
  std::string path = dir_.File("fog.vdb");
  testutil::WriteVdb(path, {grid});
  for (double threshold : {0.0, 0.5}) {
    IngestOptions o = Opts(path);
    if (threshold != 0.0) o.threshold = threshold;
    auto r = RunFake(o);
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    ExpectSameVoxels(r.store, *grid, false, threshold);
    EXPECT_EQ(r.store.meta.grid_class, GridClass::kFogVolume);
    EXPECT_TRUE(r.store.meta.has_density);
    EXPECT_FALSE(r.store.meta.has_normal);
    auto src = SourceOccupied(*grid, false, threshold);
    for (const auto& [ijk, attr] : r.store.Voxels()) ASSERT_EQ(attr.density, float(src[ijk]));
  }
}

TEST_F(IngestTest, ActiveTilesAreExpanded) {
  // A fog grid with a whole active 128^3 tile, a few voxels around it, and an
  // inactive tile that must not count.
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setName("tiles");
  grid->tree().addTile(2, Coord(-128, 0, 0), 0.25f, true);
  grid->tree().addTile(2, Coord(256, 0, 0), 0.75f, false);
  grid->tree().setValueOn(Coord(3, 4, 5), 0.5f);
  grid->tree().setValueOn(Coord(-129, 0, 0), 0.0f);  // active, not > threshold
  std::string path = dir_.File("tiles.vdb");
  testutil::WriteVdb(path, {grid});
  auto r = RunFake(Opts(path));
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  EXPECT_EQ(r.stats->occupied_tile_voxels, 128u * 128u * 128u);
  ExpectSameVoxels(r.store, *grid, false, 0.0);
  auto v = r.store.Voxels();
  EXPECT_EQ(v.at(Ijk{-100, 5, 127}).density, 0.25f);
  EXPECT_EQ(v.at(Ijk{3, 4, 5}).density, 0.5f);
  EXPECT_EQ(r.store.meta.bbox_min, glm::i64vec3(-128, 0, 0));
  EXPECT_EQ(r.store.meta.bbox_max, glm::i64vec3(3, 127, 127));
}

TEST_F(IngestTest, ScaledRotatedTransform) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      10.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
  m.preScale(openvdb::Vec3d(0.25, 0.25, 0.25));
  m.postRotate(openvdb::math::X_AXIS, 0.3);
  m.postRotate(openvdb::math::Z_AXIS, -1.1);
  m.postTranslate(openvdb::Vec3d(10.0, -20.0, 3.5));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  grid->setName("rot");
  std::string path = dir_.File("rot.vdb");
  testutil::WriteVdb(path, {grid});
  auto r = RunFake(Opts(path));
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  ExpectSameVoxels(r.store, *grid, true, 0.0);
  ExpectNormals(r.store, *grid);
  ExpectTransform(r.store.meta, *grid);
  EXPECT_NEAR(r.store.meta.voxel_size, 0.25, 1e-12);
}

TEST_F(IngestTest, SingleVoxel) {
  auto grid = openvdb::FloatGrid::create(3.0f);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->setName("one");
  grid->tree().setValueOn(Coord(-1000, 7, -3), -1.0f);
  std::string path = dir_.File("one.vdb");
  testutil::WriteVdb(path, {grid});
  auto r = RunFake(Opts(path));
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  ASSERT_EQ(r.store.Voxels().size(), 1u);
  EXPECT_TRUE(r.store.Voxels().count(Ijk{-1000, 7, -3}));
  EXPECT_EQ(r.store.meta.bbox_min, glm::i64vec3(-1000, 7, -3));
  EXPECT_EQ(r.store.meta.bbox_max, glm::i64vec3(-1000, 7, -3));
  EXPECT_EQ(r.store.meta.levels, 6);  // one 32^3 brick under one resident level
  EXPECT_EQ(r.store.meta.brick_level, 1);
  EXPECT_EQ(r.store.meta.origin, glm::i64vec3(-1024, 0, -32));
  ExpectPlacement(r.store);
}

TEST_F(IngestTest, EmptyGridsMakeEmptyStores) {
  // No active voxel at all, and active voxels none of which is occupied.
  auto none = openvdb::FloatGrid::create(3.0f);
  none->setGridClass(openvdb::GRID_LEVEL_SET);
  none->setName("none");
  auto outside = openvdb::FloatGrid::create(3.0f);
  outside->setGridClass(openvdb::GRID_LEVEL_SET);
  outside->setName("outside");
  for (int i = 0; i < 50; ++i) outside->tree().setValueOn(Coord(i * 9, -i, 2 * i), 0.5f);
  std::string path = dir_.File("empty.vdb");
  testutil::WriteVdb(path, {none, outside});
  for (const char* name : {"none", "outside"}) {
    SCOPED_TRACE(name);
    auto r = RunFake(Opts(path, name));
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    EXPECT_TRUE(r.store.finished);
    EXPECT_TRUE(r.store.bricks.empty());
    EXPECT_GT(r.store.meta.bbox_min[0], r.store.meta.bbox_max[0]);
    EXPECT_EQ(r.store.meta.brick_level, 1);
    EXPECT_EQ(r.store.meta.levels, 6);
  }
}

TEST_F(IngestTest, ColorGrids) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      8.0f, openvdb::Vec3f(1.0f, 2.0f, -3.0f), 0.5f, 3.0f);
  grid->setName("shape");
  // Same transform: the colour is read at the voxel itself.
  auto rgb = openvdb::Vec3fGrid::create(openvdb::Vec3f(0.0f));
  rgb->setTransform(grid->transform().copy());
  rgb->setName("rgb");
  for (auto it = grid->cbeginValueOn(); it; ++it) {
    Coord c = it.getCoord();
    rgb->tree().setValueOn(c, openvdb::Vec3f(c.x() * 0.01f, c.y() * 0.02f, c.z() * 0.03f));
  }
  // Another transform: sampled (trilinear) at the voxel's world position.
  auto coarse = openvdb::Vec3dGrid::create(openvdb::Vec3d(0.0));
  coarse->setTransform(openvdb::math::Transform::createLinearTransform(1.5));
  coarse->setName("coarse");
  coarse->tree().fill(openvdb::CoordBBox(Coord(-20), Coord(20)), openvdb::Vec3d(0.2, 0.4, 0.6));
  std::string path = dir_.File("color.vdb");
  testutil::WriteVdb(path, {grid, rgb, coarse});
  {
    IngestOptions o = Opts(path, "shape");
    o.color_grid = "rgb";
    auto r = RunFake(o);
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    EXPECT_TRUE(r.store.meta.has_color);
    ExpectSameVoxels(r.store, *grid, true, 0.0);
    for (const auto& [ijk, attr] : r.store.Voxels())
      ASSERT_EQ(attr.color, glm::vec3(ijk[0] * 0.01f, ijk[1] * 0.02f, ijk[2] * 0.03f));
  }
  {
    IngestOptions o = Opts(path, "shape");
    o.color_grid = "coarse";
    auto r = RunFake(o);
    ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
    auto acc = coarse->getConstAccessor();
    for (const auto& [ijk, attr] : r.store.Voxels()) {
      openvdb::Vec3d p = coarse->transform().worldToIndex(
          grid->transform().indexToWorld(Coord(ijk[0], ijk[1], ijk[2])));
      openvdb::Vec3d want;
      openvdb::tools::BoxSampler::sample(acc, p, want);
      ASSERT_NEAR(attr.color.x, want[0], 1e-6);
      ASSERT_NEAR(attr.color.z, want[2], 1e-6);
    }
  }
}

TEST_F(IngestTest, ExplicitLevelsAndThreads) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      15.0f, openvdb::Vec3f(-50.0f, 0.0f, 20.0f), 1.0f, 3.0f);
  grid->setName("s");
  std::string path = dir_.File("levels.vdb");
  testutil::WriteVdb(path, {grid});
  for (const char* levels : {"3+3", "2+4", "1+6", "4+2", "5+1", "1+20", "20+1"}) {
    for (int threads : {1, 2}) {
      SCOPED_TRACE(std::string(levels) + " threads " + std::to_string(threads));
      IngestOptions o = Opts(path);
      o.levels = levels;
      o.threads = threads;
      auto r = RunFake(o);
      ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
      auto lv = ParseLevels(levels);
      ASSERT_TRUE(lv.ok());
      EXPECT_EQ(r.store.meta.brick_level, lv->brick_level);
      EXPECT_EQ(r.store.meta.levels, lv->brick_level + lv->brick_depth);
      ExpectSameVoxels(r.store, *grid, true, 0.0);
      ExpectNormals(r.store, *grid);
    }
  }
  // 2+3 covers 32 voxels per axis; the sphere needs 64.
  IngestOptions o = Opts(path);
  o.levels = "2+3";
  auto r = RunFake(o);
  ASSERT_FALSE(r.stats.ok());
  EXPECT_EQ(r.stats.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.stats.status().message().find("2^5"), std::string::npos)
      << r.stats.status().message();
  EXPECT_TRUE(r.store.bricks.empty());
}

// ---------------------------------------------------------------------------
// Bad input: each a clear error naming the problem and the file.

void ExpectError(const StatusOr<IngestStats>& s, StatusCode code,
                 std::initializer_list<std::string> words) {
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), code) << s.status().ToString();
  for (const std::string& w : words)
    EXPECT_NE(s.status().message().find(w), std::string::npos)
        << "'" << w << "' not in: " << s.status().message();
}

TEST_F(IngestTest, NotAVdbFile) {
  std::string path = dir_.File("text.vdb");
  std::ofstream(path) << "this is not a VDB file, just some text\n";
  auto r = RunFake(Opts(path));
  ExpectError(r.stats, StatusCode::kCorruption, {path, "not a readable OpenVDB file"});
  EXPECT_FALSE(r.store.created);
  std::string empty = dir_.File("zero.vdb");
  std::ofstream(empty).flush();
  ExpectError(RunFake(Opts(empty)).stats, StatusCode::kCorruption, {empty});
}

TEST_F(IngestTest, MissingInputFile) {
  std::string path = dir_.File("nope.vdb");
  ExpectError(RunFake(Opts(path)).stats, StatusCode::kNotFound, {path});
  ExpectError(RunFake(Opts(dir_.path())).stats, StatusCode::kInvalidArgument, {"regular file"});
}

TEST_F(IngestTest, TruncatedVdbFiles) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      12.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  grid->setName("s");
  std::string full = dir_.File("full.vdb");
  testutil::WriteVdb(full, {grid});
  const auto size = std::filesystem::file_size(full);
  std::ifstream in(full, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Cut in the header, the grid descriptors, the topology and the leaf data.
  std::vector<size_t> cuts = {4, 8, 12, 20, 40, 60, 80, 100, 117, 121, 150};
  for (double frac : {0.01, 0.05, 0.2, 0.5, 0.8, 0.95, 0.999}) cuts.push_back(size_t(double(size) * frac));
  cuts.push_back(size - 1);
  for (size_t keep : cuts) {
    SCOPED_TRACE("kept " + std::to_string(keep) + " of " + std::to_string(size) + " bytes");
    std::string cut = dir_.File("cut" + std::to_string(keep) + ".vdb");
    std::ofstream(cut, std::ios::binary).write(bytes.data(), std::streamsize(keep));
    auto r = RunFake(Opts(cut));
    ASSERT_FALSE(r.stats.ok()) << "a truncated file was ingested";
    EXPECT_NE(r.stats.status().message().find(cut), std::string::npos)
        << r.stats.status().ToString();
    EXPECT_FALSE(r.store.finished);
  }
}

TEST_F(IngestTest, CorruptLeafDataIsAnErrorNotACrash) {
  // Bytes flipped inside the compressed leaf data: OpenVDB throws while
  // decoding (and its LeafBuffer is left inconsistent); the ingest must turn
  // that into a Status naming the file, from the bbox scan or from the
  // parallel brick stage, and never crash.
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      12.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  grid->setName("s");
  std::string full = dir_.File("full.vdb");
  testutil::WriteVdb(full, {grid});
  std::ifstream in(full, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  int errors = 0;
  for (double frac : {0.1, 0.3, 0.5, 0.7, 0.9, 0.98}) {
    std::string b = bytes;
    size_t at = size_t(double(b.size()) * frac);
    for (size_t i = 0; i < 64 && at + i < b.size(); ++i) b[at + i] ^= 0x5a;
    std::string path = dir_.File("corrupt" + std::to_string(at) + ".vdb");
    std::ofstream(path, std::ios::binary).write(b.data(), std::streamsize(b.size()));
    for (int threads : {1, 2}) {
      IngestOptions o = Opts(path);
      o.threads = threads;
      auto r = RunFake(o);
      if (r.stats.ok()) continue;  // the flip hit bytes that do not matter
      ++errors;
      // Corruption, or ResourceExhausted when a garbage length made OpenVDB
      // attempt a huge allocation.
      EXPECT_TRUE(r.stats.status().code() == StatusCode::kCorruption ||
                  r.stats.status().code() == StatusCode::kResourceExhausted)
          << r.stats.status().ToString();
      EXPECT_NE(r.stats.status().message().find(path), std::string::npos);
      EXPECT_FALSE(r.store.finished);
    }
  }
  EXPECT_GE(errors, 4) << "flipped leaf data went unnoticed";
}

TEST_F(IngestTest, MissingGridName) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f),
                                                                       1.0f, 3.0f);
  grid->setName("present");
  std::string path = dir_.File("named.vdb");
  testutil::WriteVdb(path, {grid});
  ExpectError(RunFake(Opts(path, "absent")).stats, StatusCode::kNotFound,
              {path, "'absent'", "'present'"});
  IngestOptions o = Opts(path);
  o.color_grid = "paint";
  ExpectError(RunFake(o).stats, StatusCode::kNotFound, {path, "'paint'"});
}

TEST_F(IngestTest, WrongGridTypes) {
  auto vec = openvdb::Vec3fGrid::create();
  vec->setName("velocity");
  vec->tree().setValueOn(Coord(1, 2, 3), openvdb::Vec3f(1.0f));
  auto ints = openvdb::Int32Grid::create();
  ints->setName("labels");
  ints->tree().setValueOn(Coord(1, 2, 3), 7);
  auto mask = openvdb::BoolGrid::create();
  mask->setName("mask");
  mask->tree().setValueOn(Coord(1, 2, 3), true);
  std::string path = dir_.File("types.vdb");
  testutil::WriteVdb(path, {vec, ints, mask});
  ExpectError(RunFake(Opts(path, "velocity")).stats, StatusCode::kUnsupported,
              {path, "'velocity'", "vec3s"});
  ExpectError(RunFake(Opts(path, "labels")).stats, StatusCode::kUnsupported,
              {path, "'labels'", "int32"});
  ExpectError(RunFake(Opts(path, "mask")).stats, StatusCode::kUnsupported, {path, "'mask'"});
  ExpectError(RunFake(Opts(path)).stats, StatusCode::kNotFound, {path, "no float or double grid"});
  // A colour grid must be a vec3 grid.
  auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      5.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  sphere->setName("s");
  std::string path2 = dir_.File("types2.vdb");
  testutil::WriteVdb(path2, {sphere, ints});
  IngestOptions o = Opts(path2, "s");
  o.color_grid = "labels";
  ExpectError(RunFake(o).stats, StatusCode::kUnsupported, {path2, "'labels'"});
}

TEST_F(IngestTest, FrustumTransformRefused) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f),
                                                                       1.0f, 3.0f);
  grid->setName("frustum");
  grid->setTransform(openvdb::math::Transform::createFrustumTransform(
      openvdb::BBoxd(openvdb::Vec3d(0.0), openvdb::Vec3d(100.0)), 0.5, 2.0, 1.0));
  std::string path = dir_.File("frustum.vdb");
  testutil::WriteVdb(path, {grid});
  ExpectError(RunFake(Opts(path)).stats, StatusCode::kUnsupported,
              {path, "'frustum'", "non-linear"});
}

TEST_F(IngestTest, ClassAndOptionConflicts) {
  auto unknown = openvdb::FloatGrid::create();
  unknown->setName("u");
  unknown->tree().setValueOn(Coord(0), 1.0f);
  auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f),
                                                                     1.0f, 3.0f);
  ls->setName("ls");
  std::string path = dir_.File("classes.vdb");
  testutil::WriteVdb(path, {unknown, ls});
  ExpectError(RunFake(Opts(path, "u")).stats, StatusCode::kInvalidArgument,
              {path, "'u'", "--threshold"});
  IngestOptions o = Opts(path, "u");
  o.threshold = 0.5;
  auto r = RunFake(o);
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  EXPECT_EQ(r.store.meta.grid_class, GridClass::kFogVolume);
  EXPECT_EQ(r.store.Voxels().size(), 1u);
  o = Opts(path, "ls");
  o.threshold = 0.5;
  ExpectError(RunFake(o).stats, StatusCode::kInvalidArgument, {"level set"});
  o.isovalue = 0.5;
  ExpectError(RunFake(o).stats, StatusCode::kInvalidArgument, {"exclude"});
  o = Opts(path, "ls");
  o.zstd_level = 0;
  ExpectError(RunFake(o).stats, StatusCode::kInvalidArgument, {"zstd"});
  o = Opts(path, "ls");
  o.levels = "9";
  ExpectError(RunFake(o).stats, StatusCode::kInvalidArgument, {"--levels"});
  for (int bits : {7, 17}) {
    o = Opts(path, "ls");
    o.normal_bits = bits;
    ExpectError(RunFake(o).stats, StatusCode::kInvalidArgument, {"normal", "8..16"});
  }
  // The normal precision reaches the writer and the options recorded in the store.
  o = Opts(path, "ls");
  o.normal_bits = 12;
  r = RunFake(o);
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  EXPECT_EQ(r.store.options.normal_bits, 12);
  EXPECT_NE(r.store.meta.build_options.find("normal_bits=12"), std::string::npos)
      << r.store.meta.build_options;
}

TEST_F(IngestTest, ExistingTargetNeedsForce) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0.0f),
                                                                       1.0f, 3.0f);
  std::string path = dir_.File("s.vdb");
  testutil::WriteVdb(path, {grid});
  std::string target = dir_.File("store");
  ASSERT_EQ(::mkdir(target.c_str(), 0755), 0);
  IngestOptions o = Opts(path);
  o.output = target;
  auto r = RunFake(o);
  ExpectError(r.stats, StatusCode::kInvalidArgument, {target, "--force"});
  EXPECT_FALSE(r.store.created);
  o.force = true;
  r = RunFake(o);
  ASSERT_TRUE(r.stats.ok()) << r.stats.status().ToString();
  EXPECT_TRUE(r.store.force);
}

TEST_F(IngestTest, WriterFailuresAbortTheIngest) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      30.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
  std::string path = dir_.File("s.vdb");
  testutil::WriteVdb(path, {grid});
  for (int fail_at : {0, 1, 5}) {
    SCOPED_TRACE(fail_at);
    FakeStore store;
    store.fail_add_at = fail_at;
    IngestOptions o = Opts(path);
    o.output = dir_.File("never");
    o.threads = 2;
    auto s = IngestWithWriter(o, store.Factory());
    ExpectError(s, StatusCode::kIoError, {"No space left"});
    EXPECT_FALSE(store.finished);
    // Bricks already in flight in other threads may still land; none after.
    EXPECT_GE(int(store.bricks.size()), fail_at);
    EXPECT_LE(int(store.bricks.size()), fail_at + 8);
  }
  FakeStore store;
  store.fail_create = true;
  IngestOptions o = Opts(path);
  o.output = dir_.File("never");
  ExpectError(IngestWithWriter(o, store.Factory()), StatusCode::kIoError, {"cannot create"});
  FakeStore store2;
  store2.fail_finish = true;
  ExpectError(IngestWithWriter(o, store2.Factory()), StatusCode::kIoError, {"fsync"});
}

}  // namespace
}  // namespace vox

// The coordinate convention and the values vox reads out of a store, against
// OpenVDB's own answers for the same grids: vox-probe's hits against the
// openvdb::Coord that holds each point; storage/sample.h's points, boxes and
// trilinear values against the grid's values, OpenVDB's BoxSampler and the
// level set's gradient.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <gtest/gtest.h>
#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/ingest.h"
#include "storage/sample.h"
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


// A sparse fog: random voxels of a 24^3 box around the origin, random densities.
openvdb::FloatGrid::Ptr RandomFog(unsigned seed) {
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  g->setName("density");
  auto acc = g->getAccessor();
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> pos(-12, 11);
  std::uniform_real_distribution<float> den(0.05f, 1.0f);
  for (int n = 0; n < 3000; ++n) acc.setValue(Coord(pos(rng), pos(rng), pos(rng)), den(rng));
  return g;
}

std::unique_ptr<StoreValues> OpenValues(const std::string& store, int level = 0) {
  auto v = StoreValues::Open(store, level, size_t(16) << 20);
  EXPECT_TRUE(v.ok()) << v.status().ToString();
  return v.ok() ? std::move(v).value() : nullptr;
}

TEST_F(ValuesTest, NearestAndBoxMatchTheFogsDensities) {
  auto grid = RandomFog(1);
  auto values = OpenValues(IngestGrid(grid, "fog"));
  ASSERT_NE(values, nullptr);
  auto acc = grid->getConstAccessor();
  // Points anywhere in the voxels, on their faces too, in OpenVDB's index space.
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-11.4, 11.4);
  std::vector<glm::dvec3> points;
  std::vector<openvdb::Vec3d> q;
  for (int n = 0; n < 4000; ++n) {
    openvdb::Vec3d p(u(rng), u(rng), u(rng));
    if (n % 4 == 0) p = openvdb::Vec3d(std::round(p.x()) - 0.5, std::round(p.y()), std::round(p.z()) - 0.5);
    q.push_back(p);
    points.push_back(glm::dvec3(p.x(), p.y(), p.z()) + 0.5);
  }
  auto s = values->Sample(points, SampleMode::kNearest);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  int occupied = 0;
  for (size_t i = 0; i < q.size(); ++i) {
    const Coord c = Coord::round(q[i]);
    const bool on = acc.isValueOn(c);
    occupied += on;
    ASSERT_TRUE(s->inside[i]) << i;
    EXPECT_EQ(s->occupancy[i], on ? 1.0f : 0.0f) << c;
    EXPECT_EQ(s->density[i], on ? acc.getValue(c) : 0.0f) << c;
  }
  EXPECT_GT(occupied, 100);
  // A box, half-open, straddling the occupied box's corner.
  const glm::i64vec3 lo(-14, -3, 5), hi(3, 9, 15);
  std::vector<float> box(size_t(StoreValues::ReadBytes(lo, hi, ValueAttr::kDensity) / sizeof(float)), -1.0f);
  ASSERT_TRUE(values->Read(lo, hi, ValueAttr::kDensity, box.data()).ok());
  size_t i = 0;
  for (int64_t x = lo.x; x < hi.x; ++x)
    for (int64_t y = lo.y; y < hi.y; ++y)
      for (int64_t z = lo.z; z < hi.z; ++z, ++i) {
        const Coord c(static_cast<int>(x), static_cast<int>(y), static_cast<int>(z));
        ASSERT_EQ(box[i], acc.isValueOn(c) ? acc.getValue(c) : 0.0f) << c;
      }
  // Outside the occupied box: NaN and a mask.
  const glm::dvec3 far[] = {{40.0, 0.0, 0.0}, {-12.6, 0.0, 0.0}};
  auto o = values->Sample(far, SampleMode::kTrilinear);
  ASSERT_TRUE(o.ok());
  for (int k = 0; k < 2; ++k) {
    EXPECT_FALSE(o->inside[size_t(k)]);
    EXPECT_TRUE(std::isnan(o->density[size_t(k)]));
  }
}

TEST_F(ValuesTest, TrilinearIsOpenVdbsBoxSampler) {
  auto grid = RandomFog(3);
  auto values = OpenValues(IngestGrid(grid, "fog3"));
  ASSERT_NE(values, nullptr);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-10.0, 10.0);
  std::vector<glm::dvec3> points;
  std::vector<openvdb::Vec3d> q;
  for (int n = 0; n < 3000; ++n) {
    q.emplace_back(u(rng), u(rng), u(rng));
    points.push_back(glm::dvec3(q.back().x(), q.back().y(), q.back().z()) + 0.5);
  }
  auto s = values->Sample(points, SampleMode::kTrilinear);
  ASSERT_TRUE(s.ok());
  for (size_t i = 0; i < q.size(); ++i)
    EXPECT_NEAR(s->density[i], openvdb::tools::BoxSampler::sample(grid->tree(), q[i]), 2e-6) << q[i];
}

TEST_F(ValuesTest, LevelSetOccupancyExactAndNormalsWithinQuantisation) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(9.3f, openvdb::Vec3f(0.7f, -0.4f, 0.2f), 1.0f, 3.0f);
  grid->setName("ls");
  auto values = OpenValues(IngestGrid(grid, "sphere"));
  ASSERT_NE(values, nullptr);
  EXPECT_TRUE(values->meta().has_normal);
  const glm::i64vec3 lo(-14, -14, -14), hi(14, 14, 14);
  std::vector<float> occ(size_t(StoreValues::ReadBytes(lo, hi, ValueAttr::kOccupancy) / 4));
  std::vector<float> nor(size_t(StoreValues::ReadBytes(lo, hi, ValueAttr::kNormal) / 4));
  ASSERT_TRUE(values->Read(lo, hi, ValueAttr::kOccupancy, occ.data()).ok());
  ASSERT_TRUE(values->Read(lo, hi, ValueAttr::kNormal, nor.data()).ok());
  auto acc = grid->getConstAccessor();
  const openvdb::math::UniformScaleMap map;
  size_t i = 0, surface = 0;
  for (int x = -14; x < 14; ++x)
    for (int y = -14; y < 14; ++y)
      for (int z = -14; z < 14; ++z, ++i) {
        const Coord c(x, y, z);
        const bool on = acc.isValueOn(c) && acc.getValue(c) <= 0.0f;
        ASSERT_EQ(occ[i], on ? 1.0f : 0.0f) << c;
        if (!on) continue;
        openvdb::Vec3f g = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc, c);
        if (g.length() < 1e-6f) continue;
        g.normalize();
        ++surface;
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(nor[i * 3 + size_t(k)], g[k], 1e-3) << c;
      }
  EXPECT_GT(surface, 1000u);
}

// vox-probe --at prints the wall's densities as OpenVDB holds them, and
// --slice writes the plane x = 5 as an EXR whose pixels are the grid's.
TEST_F(ValuesTest, ProbeAtAndSliceFromTheCommandLine) {
  auto grid = Wall();
  const std::string store = IngestGrid(grid, "wall2");
  auto acc = grid->getConstAccessor();
  auto r = testing::RunCommand(std::string(VOX_PROBE_BIN) + " " + store +
                               " --at 5.5 -0.2 0.5 --at 5.2 2.9 -2.1 --at 4.9 0 0 --at 50 0 0");
  ASSERT_EQ(r.code, 0) << r.output;
  std::istringstream out(r.output);
  const Coord expect[] = {Coord(5, -1, 0), Coord(5, 2, -3)};
  for (const Coord& c : expect) {
    double x, y, z, occ, den;
    std::string inside, w1, w2;
    ASSERT_TRUE(out >> x >> y >> z >> inside >> w1 >> occ >> w2 >> den) << r.output;
    EXPECT_EQ(inside, "inside");
    EXPECT_EQ(occ, 1.0);
    EXPECT_EQ(float(den), acc.getValue(c)) << c;
  }
  std::string line;
  std::getline(out, line);
  std::getline(out, line);
  EXPECT_EQ(line, "4.9 0 0 outside occupancy nan density nan");
  std::getline(out, line);
  EXPECT_EQ(line, "50 0 0 outside occupancy nan density nan");
  const std::string exr = dir_.File("slice.exr");
  r = testing::RunCommand(std::string(VOX_PROBE_BIN) + " " + store + " --slice x 5 -o " + exr);
  ASSERT_EQ(r.code, 0) << r.output;
  Imf::InputFile in(exr.c_str());
  const Imath::Box2i dw = in.header().dataWindow();
  const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
  ASSERT_EQ(w, 7);  // y from -3 to 3 across, z from -3 to 3 down
  ASSERT_EQ(h, 7);
  std::vector<float> px(size_t(w) * size_t(h));
  Imf::FrameBuffer fb;
  fb.insert("density", Imf::Slice(Imf::FLOAT, (char*)px.data(), sizeof(float), sizeof(float) * size_t(w)));
  in.setFrameBuffer(fb);
  in.readPixels(dw.min.y, dw.max.y);
  for (int row = 0; row < h; ++row)
    for (int col = 0; col < w; ++col)
      EXPECT_EQ(px[size_t(row * w + col)], acc.getValue(Coord(5, col - 3, row - 3))) << col << " " << row;
  // Bad input: a clear message, no file.
  r = testing::RunCommand(std::string(VOX_PROBE_BIN) + " " + store + " --slice x 5 -o " + exr + ".2 --attr normal");
  EXPECT_EQ(r.code, 1);  // the store cannot serve it
  EXPECT_NE(r.output.find("attribute 'normal': this store keeps occupancy, density"), std::string::npos) << r.output;
}

// The bytes of a file.
std::string FileBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Stores a and b hold the same metadata (the id and the input's name aside)
// and the same bricks, voxel for voxel.
void ExpectSameStore(const std::string& a, const std::string& b) {
  auto sa = Store::Open(a, OpenOptions{});
  auto sb = Store::Open(b, OpenOptions{});
  ASSERT_TRUE(sa.ok() && sb.ok()) << sa.status().ToString() << sb.status().ToString();
  const StoreMeta &ma = (*sa)->meta(), &mb = (*sb)->meta();
  EXPECT_EQ(ma.grid_name, mb.grid_name);
  EXPECT_EQ(ma.grid_class, mb.grid_class);
  EXPECT_EQ(ma.levels, mb.levels);
  EXPECT_EQ(ma.brick_level, mb.brick_level);
  EXPECT_EQ(ma.origin, mb.origin);
  EXPECT_EQ(ma.bbox_min, mb.bbox_min);
  EXPECT_EQ(ma.bbox_max, mb.bbox_max);
  EXPECT_EQ(ma.index_to_world, mb.index_to_world);
  EXPECT_EQ(ma.voxel_size, mb.voxel_size);
  EXPECT_EQ(ma.voxel_count, mb.voxel_count);
  EXPECT_EQ(ma.brick_count, mb.brick_count);
  EXPECT_EQ(ma.top_cells, mb.top_cells);
  EXPECT_EQ(ma.has_density, mb.has_density);
  EXPECT_EQ(ma.has_normal, mb.has_normal);
  EXPECT_EQ(ma.threshold, mb.threshold);
  // The bricks: the same voxels at the same brick and payload (the brick
  // file's bytes differ: its header and record checksums carry the store_id).
  auto va = testutil::ReadAll(**sa);
  auto vb = testutil::ReadAll(**sb);
  ASSERT_TRUE(va.ok() && vb.ok());
  ASSERT_EQ(va->size(), vb->size());
  for (const auto& [ijk, at] : *va) {
    auto it = vb->find(ijk);
    ASSERT_NE(it, vb->end());
    EXPECT_EQ(at.brick, it->second.brick);
    EXPECT_EQ(at.payload, it->second.payload);
    auto x = (*sa)->Attributes(at.brick, at.payload);
    auto y = (*sb)->Attributes(it->second.brick, it->second.payload);
    ASSERT_TRUE(x.ok() && y.ok());
    EXPECT_EQ(x->density, y->density);
  }
}

// The same data through a .vdb (built here with OpenVDB, every element
// active), a .npy and a raw file: the same store.
TEST_F(ValuesTest, NpyAndRawGiveTheStoreOfTheSameVdb) {
  const int nx = 20, ny = 16, nz = 12;
  const int ox = -7, oy = 3, oz = -2;
  std::vector<float> data(size_t(nx) * ny * nz);
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
  auto acc = grid->getAccessor();
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k) {
        const float v = 0.5f + 0.5f * std::sin(0.7f * float(i)) * std::cos(0.45f * float(j + k));
        data[(size_t(i) * ny + j) * nz + k] = v;
        acc.setValueOn(Coord(i + ox, j + oy, k + oz), v);
      }
  const std::string vdb = dir_.File("ref.vdb");
  testutil::WriteVdb(vdb, {grid});
  IngestOptions o;
  o.input = vdb;
  o.output = dir_.File("ref.store");
  o.threshold = 0.3;
  ASSERT_TRUE(Ingest(o).ok());
  // data.npy: format 1.0, its header padded to 64 bytes.
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (20, 16, 12), }";
  while ((10 + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::string npy = std::string("\x93NUMPY\x01\x00", 8);
  npy += char(header.size() & 0xff);
  npy += char(header.size() >> 8);
  npy += header;
  const std::string raw(reinterpret_cast<const char*>(data.data()), data.size() * sizeof(float));
  std::ofstream(dir_.File("data.npy"), std::ios::binary) << npy << raw;
  std::ofstream(dir_.File("data.raw"), std::ios::binary) << raw;
  const std::string ingest = std::string(VOX_INGEST_BIN) + " --quiet --voxel-size 0.25 --origin -7,3,-2 --threshold 0.3 ";
  auto r = testing::RunCommand(ingest + dir_.File("data.npy") + " " + dir_.File("npy.store"));
  ASSERT_EQ(r.code, 0) << r.output;
  ExpectSameStore(o.output, dir_.File("npy.store"));
  {  // The store names the array file as its source.
    auto npy_store = Store::Open(dir_.File("npy.store"), OpenOptions{});
    ASSERT_TRUE(npy_store.ok());
    EXPECT_EQ((*npy_store)->meta().source_file, dir_.File("data.npy"));
  }
  r = testing::RunCommand(ingest + "--shape 20,16,12 --dtype float32 " + dir_.File("data.raw") + " " +
                          dir_.File("raw.store"));
  ASSERT_EQ(r.code, 0) << r.output;
  ExpectSameStore(o.output, dir_.File("raw.store"));
  // No temporary is left beside the outputs.
  for (const auto& e : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_NE(e.path().filename().string()[0], '.') << e.path();  // no .NAME.tmp-* or .NAME.input-*
  // Bad input: the file and the problem named, no store.
  r = testing::RunCommand(std::string(VOX_INGEST_BIN) + " --shape 20,16,13 --dtype float32 " + dir_.File("data.raw") +
                          " " + dir_.File("bad.store"));
  EXPECT_EQ(r.code, 1);  // the file does not match its --shape: an input that cannot be read
  EXPECT_NE(r.output.find("data.raw' has 15360 bytes; shape 20 x 16 x 13 of float32 needs 16640"), std::string::npos)
      << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir_.File("bad.store")));
}

}  // namespace
}  // namespace vox

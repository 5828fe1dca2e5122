// Round trip: stores written from generated shapes reopen with every voxel,
// attribute and metadata field intact, and trace exactly like MemoryOctree.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <random>
#include <set>

#include <glm/geometric.hpp>

#include "core/tracer.h"
#include "core/util/crc32c.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using storage_test::TempDir;

TEST(Crc32c, KnownValues) {
  // RFC 3720 B.4 test vectors and the classic check value.
  EXPECT_EQ(crc32c::Value("123456789", 9), 0xE3069283u);
  std::string zeros(32, '\0'), ones(32, '\xff');
  EXPECT_EQ(crc32c::Value(zeros.data(), 32), 0x8A9136AAu);
  EXPECT_EQ(crc32c::Value(ones.data(), 32), 0x62A8AB43u);
  std::string inc(32, 0);
  for (int i = 0; i < 32; ++i) inc[i] = char(i);
  EXPECT_EQ(crc32c::Value(inc.data(), 32), 0x46DD794Eu);
  // Extend over pieces equals the whole, at every alignment.
  std::string s = "The quick brown fox jumps over the lazy dog, twice over.";
  for (size_t k = 0; k <= s.size(); ++k)
    EXPECT_EQ(crc32c::Extend(crc32c::Value(s.data(), k), s.data() + k, s.size() - k),
              crc32c::Value(s.data(), s.size()));
  uint32_t c = crc32c::Value(s.data(), s.size());
  EXPECT_NE(crc32c::Mask(c), c);
  EXPECT_EQ(crc32c::Unmask(crc32c::Mask(c)), c);
}

TEST(Crc32c, FastPathEqualsTables) {
  // Random lengths, alignments and seeds: the instruction path (where the
  // CPU has one) and the tables agree.
  std::mt19937 rng(7);
  std::vector<uint8_t> buf(4096 + 16);
  for (uint8_t& b : buf) b = uint8_t(rng());
  for (int i = 0; i < 2000; ++i) {
    const size_t at = rng() % 16, n = rng() % 4096;
    const uint32_t seed = i % 2 ? uint32_t(rng()) : 0;
    ASSERT_EQ(crc32c::Extend(seed, buf.data() + at, n),
              crc32c::ExtendPortable(seed, buf.data() + at, n))
        << "at " << at << " n " << n;
  }
}

TEST(OctNormal, RoundTripWithinQuantisation) {
  // Maximum angular error (degrees) by precision, measured on random normals
  // and on the axes and octant diagonals.
  for (auto [bits, max_deg] : {std::pair{16, 0.005}, {12, 0.07}, {8, 1.2}}) {
    std::mt19937 rng(5);
    std::normal_distribution<double> g;
    double worst = 0;
    std::vector<glm::dvec3> ns = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1},
                                  {0, 0, -1}, {1, 1, 1}, {-1, -1, -1}, {1, -1, 1}};
    for (int i = 0; i < 20000; ++i) ns.push_back({g(rng), g(rng), g(rng)});
    for (glm::dvec3 n : ns) {
      n /= std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
      uint32_t code = storage_internal::EncodeOctNormal(glm::vec3(n), bits);
      const uint32_t step = 1u << (16 - bits);
      ASSERT_EQ((code & 0xffff) % step, 0u);
      ASSERT_EQ((code >> 16) % step, 0u);
      glm::dvec3 d(storage_internal::DecodeOctNormal(code));
      glm::dvec3 x(n.y * d.z - n.z * d.y, n.z * d.x - n.x * d.z, n.x * d.y - n.y * d.x);
      double angle = std::atan2(std::sqrt(x.x * x.x + x.y * x.y + x.z * x.z),
                                n.x * d.x + n.y * d.y + n.z * d.z);
      worst = std::max(worst, angle * 180 / M_PI);
      ASSERT_NEAR(d.x * d.x + d.y * d.y + d.z * d.z, 1.0, 1e-5);
    }
    EXPECT_LT(worst, max_deg) << bits << " bits";
    std::printf("octahedral normals, %d bits per component: max error %.4f degrees\n", bits, worst);
  }
  // Zero and NaN encode as +z.
  for (glm::vec3 bad : {glm::vec3(0), glm::vec3(NAN, 0, 1)}) {
    glm::vec3 z = storage_internal::DecodeOctNormal(storage_internal::EncodeOctNormal(bad));
    EXPECT_GT(z.z, 0.99999f);
  }
}

struct Case {
  std::string shape;
  int brick_level;
  GridClass gc;
  bool color;
};

class RoundTrip : public ::testing::TestWithParam<Case> {};

TEST_P(RoundTrip, EveryVoxelAndAttribute) {
  const Case& c = GetParam();
  auto vol = GenerateShape(c.shape);
  ASSERT_TRUE(vol.ok());
  StoreMeta meta = storage_test::MetaFor(vol->levels, std::min(c.brick_level, vol->levels), c.gc, c.color);
  TempDir tmp;
  std::string dir = tmp / "store";
  Status ws = storage_test::WriteVoxels(dir, vol->voxels, meta);
  ASSERT_TRUE(ws.ok()) << ws.ToString();
  auto store = Store::Open(dir, OpenOptions{});
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  Store& s = **store;
  const StoreMeta& m = s.meta();

  // Metadata.
  EXPECT_EQ(m.source_file, meta.source_file);
  EXPECT_EQ(m.grid_name, meta.grid_name);
  EXPECT_EQ(m.grid_class, meta.grid_class);
  EXPECT_EQ(m.levels, meta.levels);
  EXPECT_EQ(m.brick_level, meta.brick_level);
  EXPECT_EQ(m.origin, meta.origin);
  EXPECT_EQ(m.index_to_world, meta.index_to_world);
  EXPECT_EQ(m.voxel_size, meta.voxel_size);
  EXPECT_EQ(m.has_normal, meta.has_normal);
  EXPECT_EQ(m.has_density, meta.has_density);
  EXPECT_EQ(m.has_color, meta.has_color);
  EXPECT_EQ(m.isovalue, meta.isovalue);
  EXPECT_EQ(m.threshold, meta.threshold);
  EXPECT_EQ(m.build_options, meta.build_options);
  EXPECT_EQ(m.voxel_count, vol->voxels.size());
  glm::i64vec3 lo(INT64_MAX), hi(INT64_MIN);
  std::set<std::tuple<uint64_t, uint64_t, uint64_t>> bricks;
  const int sub = m.levels - m.brick_level;
  for (const LeafPoint& p : vol->voxels) {
    lo = glm::min(lo, glm::i64vec3(p.x, p.y, p.z));
    hi = glm::max(hi, glm::i64vec3(p.x, p.y, p.z));
    bricks.insert({p.x >> sub, p.y >> sub, p.z >> sub});
  }
  EXPECT_EQ(m.bbox_min, lo + meta.origin);
  EXPECT_EQ(m.bbox_max, hi + meta.origin);
  EXPECT_EQ(m.brick_count, sub == 0 ? 0 : bricks.size());
  EXPECT_EQ(m.top_cells, s.view().top_cells);

  // Every voxel is found with its attributes; payloads are distinct.
  std::set<std::pair<uint32_t, uint32_t>> seen;
  for (const LeafPoint& p : vol->voxels) {
    auto loc = storage_test::Locate(s, p.x, p.y, p.z);
    ASSERT_TRUE(loc.ok()) << loc.status().ToString();
    ASSERT_TRUE(loc->has_value()) << p.x << "," << p.y << "," << p.z;
    EXPECT_TRUE(seen.insert({(*loc)->brick, (*loc)->payload}).second);
    auto a = s.Attributes((*loc)->brick, (*loc)->payload);
    ASSERT_TRUE(a.ok()) << a.status().ToString();
    VoxelAttributes e = storage_test::AttrFor(p.x, p.y, p.z, meta);
    if (m.has_normal) {
      EXPECT_NEAR(a->normal.x, e.normal.x, 1e-3);
      EXPECT_NEAR(a->normal.y, e.normal.y, 1e-3);
      EXPECT_NEAR(a->normal.z, e.normal.z, 1e-3);
    } else {
      EXPECT_EQ(a->normal, glm::vec3(0));
    }
    EXPECT_EQ(a->density, e.density);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(a->color[k], e.color[k], 2e-3);
  }
  // The same pools, cell for cell, as MemoryOctree builds (ids in Morton order).
  auto mem = MemoryOctree::Build(vol->voxels, m.levels, m.brick_level);
  ASSERT_TRUE(mem.ok());
  ASSERT_EQ(s.view().top_cells, (*mem)->view().top_cells);
  EXPECT_EQ(0, std::memcmp(s.view().top, (*mem)->view().top, sizeof(CompactCell) * s.view().top_cells));
  for (uint32_t id = 0; id < (*mem)->num_bricks(); ++id) {
    auto a = s.FetchBrick(id);
    auto b = (*mem)->FetchBrick(id);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->num_cells, b->num_cells);
    EXPECT_EQ(0, std::memcmp(a->cells, b->cells, sizeof(CompactCell) * a->num_cells)) << "brick " << id;
  }
  // No voxel more than those written: count the leaves of the whole tree.
  uint64_t leaves = 0;
  const OctreeView v = s.view();
  std::function<void(const CompactCell*, CompactCell, int)> count =
      [&](const CompactCell* pool, CompactCell cell, int level) {
        for (unsigned d = 0; d < 8; ++d) {
          ChildRef r = ChildOf(cell, d, level, v);
          if (r.kind == ChildRef::kPayload) {
            ++leaves;
          } else if (r.kind == ChildRef::kBrick) {
            auto b = s.FetchBrick(r.index);
            ASSERT_TRUE(b.ok());
            count(b->cells, b->cells[0], level + 1);
          } else if (r.kind == ChildRef::kCell) {
            count(pool, pool[r.index], level + 1);
          }
        }
      };
  count(v.top, v.top[0], 0);
  EXPECT_EQ(leaves, vol->voxels.size());
}

TEST_P(RoundTrip, TracesLikeMemoryOctree) {
  const Case& c = GetParam();
  auto vol = GenerateShape(c.shape);
  ASSERT_TRUE(vol.ok());
  const int levels = vol->levels;
  StoreMeta meta = storage_test::MetaFor(levels, std::min(c.brick_level, levels), c.gc, c.color);
  TempDir tmp;
  std::string dir = tmp / "store";
  ASSERT_TRUE(storage_test::WriteVoxels(dir, vol->voxels, meta).ok());
  OpenOptions oo;
  oo.cache_bytes = 64 << 10;  // small: eviction while tracing
  auto store = Store::Open(dir, oo);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  auto mem = MemoryOctree::Build(vol->voxels, levels, levels);
  ASSERT_TRUE(mem.ok());
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> u(-0.3, 1.3), dd(-1, 1);
  const double n = double(int64_t(1) << levels);
  std::vector<Ray> rays;
  for (int i = 0; i < 300; ++i) {
    Ray r;
    r.origin = glm::dvec3(u(rng), u(rng), u(rng)) * n;
    r.dir = glm::dvec3(dd(rng), dd(rng), dd(rng));
    if (i % 10 == 0) r.dir = glm::dvec3(0, 0, i % 20 == 0 ? 1 : -1);  // axis-aligned
    if (i % 2 == 1) {  // aimed at a voxel's centre
      const LeafPoint& p = vol->voxels[rng() % vol->voxels.size()];
      r.dir = glm::dvec3(p.x + 0.5, p.y + 0.5, p.z + 0.5) - r.origin;
    }
    rays.push_back(r);
  }
  std::set<int> splits = {1, std::max(1, meta.brick_level - 1), meta.brick_level,
                          std::min(levels, meta.brick_level + 1), levels};
  uint64_t total_hits = 0;
  int traced = 0;
  for (int n1 : splits) {
    if (n1 > 20 || levels - n1 > 20) continue;
    ++traced;
    auto ts = Tracer<>::Create((*store)->view(), n1);
    auto tm = Tracer<>::Create((*mem)->view(), n1);
    ASSERT_TRUE(ts.ok() && tm.ok()) << ts.status().ToString();
    for (const Ray& r : rays) {
      std::vector<Hit> hs, hm;
      ASSERT_TRUE(ts->Traverse(r, [&](const Hit& h) {
                      // Read from the brick the traversal pins: as by id.
                      auto ah = (*store)->HitAttributes(h);
                      auto ai = (*store)->Attributes(h.brick, h.payload);
                      EXPECT_TRUE(ah.ok() && ai.ok());
                      EXPECT_EQ(h.brick_data == nullptr, h.brick == kNoBrick);
                      if (ah.ok() && ai.ok()) {
                        EXPECT_EQ(ah->normal, ai->normal);
                        EXPECT_EQ(ah->density, ai->density);
                        EXPECT_EQ(ah->color, ai->color);
                      }
                      hs.push_back(h);
                      return hs.size() < 8;
                    }).ok());
      ASSERT_TRUE(tm->Traverse(r, [&](const Hit& h) { hm.push_back(h); return hm.size() < 8; }).ok());
      ASSERT_EQ(hs.size(), hm.size()) << "split " << n1;
      total_hits += hs.size();
      for (size_t k = 0; k < hs.size(); ++k) {
        EXPECT_EQ(hs[k].voxel, hm[k].voxel) << "split " << n1;
        EXPECT_EQ(hs[k].t, hm[k].t);
        auto a = (*store)->Attributes(hs[k].brick, hs[k].payload);
        ASSERT_TRUE(a.ok()) << a.status().ToString();
        VoxelAttributes e = storage_test::AttrFor(hs[k].voxel.x, hs[k].voxel.y, hs[k].voxel.z, meta);
        EXPECT_NEAR(a->normal.x, e.normal.x, 1e-3);
        EXPECT_EQ(a->density, e.density);
      }
    }
  }
  if (traced > 0) {
    EXPECT_GT(total_hits, 300u);  // the comparison saw hits
  }
  CacheStats cs = (*store)->cache_stats();
  EXPECT_LE(cs.bytes_resident, cs.capacity);
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, RoundTrip,
    ::testing::Values(Case{"sphere:64", 3, GridClass::kLevelSet, false},
                      Case{"sphere:64", 1, GridClass::kLevelSet, true},
                      Case{"sphere:64", 5, GridClass::kFogVolume, false},
                      Case{"sphere:64", 6, GridClass::kLevelSet, false},  // top only
                      Case{"torus:32", 2, GridClass::kFogVolume, true},
                      Case{"cubes:64", 4, GridClass::kLevelSet, true},
                      Case{"noise:32", 3, GridClass::kFogVolume, false},
                      Case{"corner:12", 6, GridClass::kLevelSet, false},
                      Case{"corner:24", 10, GridClass::kLevelSet, true},
                      Case{"corner:26", 3, GridClass::kLevelSet, false}),  // 23-level bricks
    [](const auto& info) {
      std::string s = info.param.shape + "_bl" + std::to_string(info.param.brick_level) +
                      (info.param.gc == GridClass::kLevelSet ? "_ls" : "_fog") +
                      (info.param.color ? "_rgb" : "");
      for (char& ch : s)
        if (!isalnum(ch)) ch = '_';
      return s;
    });

TEST(Writer, CoarserNormalsShrinkTheStoreAndStayAccurate) {
  auto vol = GenerateShape("sphere:128");
  ASSERT_TRUE(vol.ok());
  StoreMeta meta = storage_test::MetaFor(vol->levels, 3, GridClass::kLevelSet, false);
  TempDir tmp;
  uint64_t sizes[2];
  for (int k = 0; k < 2; ++k) {
    WriteOptions wo;
    wo.normal_bits = k == 0 ? 16 : 12;
    std::string dir = tmp / ("s" + std::to_string(k));
    ASSERT_TRUE(storage_test::WriteVoxels(dir, vol->voxels, meta, wo).ok());
    sizes[k] = storage_test::ReadFile(dir + "/bricks.vxb").size();
    auto s = Store::Open(dir, {});
    ASSERT_TRUE(s.ok());
    for (size_t i = 0; i < vol->voxels.size(); i += 97) {
      const LeafPoint& p = vol->voxels[i];
      auto loc = storage_test::Locate(**s, p.x, p.y, p.z);
      ASSERT_TRUE(loc.ok() && loc->has_value());
      auto a = (*s)->Attributes((*loc)->brick, (*loc)->payload);
      ASSERT_TRUE(a.ok());
      glm::vec3 e = storage_test::AttrFor(p.x, p.y, p.z, meta).normal;
      EXPECT_GT(glm::dot(a->normal, e), std::cos(0.07 * M_PI / 180));
    }
  }
  EXPECT_LT(sizes[1], sizes[0]);
  WriteOptions bad;
  bad.normal_bits = 17;
  EXPECT_EQ(StoreWriter::Create(tmp / "x", meta, bad).status().code(), StatusCode::kInvalidArgument);
}

TEST(Writer, VoxelsAlreadyInMortonOrder) {
  auto vol = GenerateShape("torus:64");
  ASSERT_TRUE(vol.ok());
  std::vector<LeafPoint> v = vol->voxels;
  std::sort(v.begin(), v.end(), MortonLess);
  StoreMeta meta = storage_test::MetaFor(vol->levels, 3, GridClass::kLevelSet, false);
  TempDir tmp;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp / "s", v, meta, {}, 1, /*shuffle_voxels=*/false).ok());
  auto s = Store::Open(tmp / "s", {});
  ASSERT_TRUE(s.ok());
  auto mem = MemoryOctree::Build(v, vol->levels, 3);
  ASSERT_TRUE(mem.ok());
  for (uint32_t id = 0; id < (*mem)->num_bricks(); ++id) {
    auto a = (*s)->FetchBrick(id);
    auto b = (*mem)->FetchBrick(id);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->num_cells, b->num_cells);
    EXPECT_EQ(0, std::memcmp(a->cells, b->cells, sizeof(CompactCell) * a->num_cells));
  }
  for (size_t i = 0; i < v.size(); i += 13) {
    auto loc = storage_test::Locate(**s, v[i].x, v[i].y, v[i].z);
    ASSERT_TRUE(loc.ok() && loc->has_value());
    auto a = (*s)->Attributes((*loc)->brick, (*loc)->payload);
    ASSERT_TRUE(a.ok());
    glm::vec3 e = storage_test::AttrFor(v[i].x, v[i].y, v[i].z, meta).normal;
    EXPECT_GT(glm::dot(a->normal, e), 0.99999f);
  }
}

TEST(Writer, DeepBricksSortedWithoutKeys) {
  // 23-level bricks exceed the 63-bit Morton key: the comparator path.
  const int levels = 26, bl = 3;
  std::mt19937_64 rng(8);
  std::vector<LeafPoint> voxels;
  for (int i = 0; i < 3000; ++i) {
    uint64_t b = rng() % 3;  // three bricks along x
    uint64_t m = (uint64_t(1) << 23) - 1;
    voxels.push_back({(b << 23) | (rng() & m), rng() & m, rng() & m, kEmptyRef});
    if (i % 10 == 0)  // clusters, so bricks share cells deep down
      for (int k = 1; k < 4; ++k)
        voxels.push_back({voxels.back().x ^ uint64_t(k), voxels.back().y, voxels.back().z, kEmptyRef});
  }
  std::sort(voxels.begin(), voxels.end(), MortonLess);
  voxels.erase(std::unique(voxels.begin(), voxels.end(), [](auto& a, auto& b) {
                 return a.x == b.x && a.y == b.y && a.z == b.z;
               }), voxels.end());
  StoreMeta meta = storage_test::MetaFor(levels, bl, GridClass::kFogVolume, false);
  TempDir tmp;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp / "s", voxels, meta).ok());
  auto s = Store::Open(tmp / "s", {});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  auto mem = MemoryOctree::Build(voxels, levels, bl);
  ASSERT_TRUE(mem.ok());
  for (uint32_t id = 0; id < (*mem)->num_bricks(); ++id) {
    auto a = (*s)->FetchBrick(id);
    auto b = (*mem)->FetchBrick(id);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->num_cells, b->num_cells);
    EXPECT_EQ(0, std::memcmp(a->cells, b->cells, sizeof(CompactCell) * a->num_cells));
  }
  for (const LeafPoint& p : voxels) {
    auto loc = storage_test::Locate(**s, p.x, p.y, p.z);
    ASSERT_TRUE(loc.ok() && loc->has_value());
    auto a = (*s)->Attributes((*loc)->brick, (*loc)->payload);
    ASSERT_TRUE(a.ok());
    EXPECT_EQ(a->density, storage_test::AttrFor(p.x, p.y, p.z, meta).density);
  }
}

TEST(Writer, EmptyStoreOpens) {
  TempDir tmp;
  StoreMeta meta = storage_test::MetaFor(5, 3, GridClass::kLevelSet, false);
  auto w = StoreWriter::Create(tmp / "s", meta, {});
  ASSERT_TRUE(w.ok());
  ASSERT_TRUE((*w)->Finish().ok());
  auto s = Store::Open(tmp / "s", {});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->meta().voxel_count, 0u);
  EXPECT_EQ((*s)->meta().brick_count, 0u);
  auto t = Tracer<>::Create((*s)->view(), 3);
  ASSERT_TRUE(t.ok());
  auto h = t->FirstHit(Ray{{1, 1, -1}, {0.1, 0.2, 1}});
  ASSERT_TRUE(h.ok());
  EXPECT_FALSE(h->has_value());
}

TEST(Writer, RejectsBadBricks) {
  TempDir tmp;
  StoreMeta meta = storage_test::MetaFor(5, 3, GridClass::kLevelSet, false);
  auto w = StoreWriter::Create(tmp / "s", meta, {});
  ASSERT_TRUE(w.ok());
  EXPECT_EQ((*w)->AddBrick({8, 0, 0}, {BrickVoxel{}}).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*w)->AddBrick({1, 0, 0}, {}).code(), StatusCode::kInvalidArgument);
  BrickVoxel far;
  far.x = 4;
  EXPECT_EQ((*w)->AddBrick({1, 0, 0}, {far}).code(), StatusCode::kInvalidArgument);
  BrickVoxel a;
  EXPECT_EQ((*w)->AddBrick({2, 0, 0}, {a, a}).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE((*w)->AddBrick({3, 0, 0}, {a}).ok());
  EXPECT_EQ((*w)->AddBrick({3, 0, 0}, {a}).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace vox

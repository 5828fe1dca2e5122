// The structural checks behind the checksums: ValidatePool on hand-made bad
// pools, a top with bad refs but valid CRCs refused at open, and the brick
// decoder fed mutated bytes (never a bad pool, never a crash).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <tuple>

#include "core/shapes.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/brick_uniform.h"
#include "storage/internal/format.h"
#include "storage/internal/store_impl.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using namespace storage_internal;

uint32_t DecodeFixed32Raw(const char* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// A 3-level pool: root -> cell 1 -> cell 2 -> leaves / bricks.
std::vector<Cell> Chain(NodeRef last) {
  std::vector<Cell> c(3, Cell{});
  c[0].child[5] = 1;
  c[1].child[0] = 2;
  c[2].child[7] = last;
  return c;
}

TEST(ValidatePool, AcceptsBuildCellsOutput) {
  auto vol = GenerateShape("cubes:64");
  ASSERT_TRUE(vol.ok());
  std::vector<LeafPoint> pts = vol->voxels;
  std::sort(pts.begin(), pts.end(), MortonLess);
  pts.erase(std::unique(pts.begin(), pts.end(), [](auto& a, auto& b) {
              return a.x == b.x && a.y == b.y && a.z == b.z;
            }), pts.end());
  for (size_t i = 0; i < pts.size(); ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
  auto cells = BuildCells(pts, vol->levels);
  EXPECT_TRUE(ValidatePool(cells.data(), cells.size(), vol->levels, false, pts.size()).ok());
  EXPECT_FALSE(ValidatePool(cells.data(), cells.size(), vol->levels, false, pts.size() - 1).ok());
  EXPECT_FALSE(ValidatePool(cells.data(), cells.size(), vol->levels, true, 1u << 30).ok());
  EXPECT_FALSE(ValidatePool(cells.data(), cells.size() - 1, vol->levels, false, pts.size()).ok());
}

TEST(MaxCells, BoundsBuildCells) {
  EXPECT_EQ(MaxCells(1, 8), 1u);
  EXPECT_EQ(MaxCells(1, 9), 0u);           // more voxels than a 2^3 grid has
  EXPECT_EQ(MaxCells(3, 1), 3u);           // a chain
  EXPECT_EQ(MaxCells(3, 512), 1u + 8 + 64);  // full
  EXPECT_EQ(MaxCells(3, 10), 1u + 8 + 10);
  // BuildCells never exceeds the bound, and reaches it for a chain and a full grid.
  auto vol = GenerateShape("noise:32");
  ASSERT_TRUE(vol.ok());
  std::vector<LeafPoint> pts = vol->voxels;
  std::sort(pts.begin(), pts.end(), MortonLess);
  pts.erase(std::unique(pts.begin(), pts.end(), [](auto& a, auto& b) {
              return a.x == b.x && a.y == b.y && a.z == b.z;
            }), pts.end());
  EXPECT_LE(BuildCells(pts, 5).size(), MaxCells(5, pts.size()));
}

TEST(ValidatePool, RefusesBadPools) {
  EXPECT_TRUE(ValidatePool(Chain(MakeLeafRef(0)).data(), 3, 3, false, 1).ok());
  EXPECT_TRUE(ValidatePool(Chain(MakeBrickRef(4)).data(), 3, 3, true, 5).ok());
  // Leaf payload out of range; brick id out of range; brick ref where a leaf goes.
  EXPECT_FALSE(ValidatePool(Chain(MakeLeafRef(1)).data(), 3, 3, false, 1).ok());
  EXPECT_FALSE(ValidatePool(Chain(MakeBrickRef(5)).data(), 3, 3, true, 5).ok());
  EXPECT_FALSE(ValidatePool(Chain(MakeBrickRef(0)).data(), 3, 3, false, 1).ok());
  EXPECT_FALSE(ValidatePool(Chain(MakeLeafRef(0)).data(), 3, 3, true, 5).ok());
  // Cell ref past the pool; a cycle; a brick ref above the brick level.
  auto c = Chain(MakeLeafRef(0));
  c[1].child[0] = 9;
  EXPECT_FALSE(ValidatePool(c.data(), 3, 3, false, 1).ok());
  c = Chain(MakeLeafRef(0));
  c[1].child[0] = 0;
  EXPECT_FALSE(ValidatePool(c.data(), 3, 3, false, 1).ok());
  c = Chain(MakeLeafRef(0));
  c[0].child[5] = MakeBrickRef(0);
  EXPECT_FALSE(ValidatePool(c.data(), 3, 3, true, 5).ok());
  // Two refs to the same cell (a DAG, exponential to walk) and an unreached cell.
  c = Chain(MakeLeafRef(0));
  c[0].child[6] = 1;
  EXPECT_FALSE(ValidatePool(c.data(), 3, 3, false, 1).ok());
  c = Chain(MakeLeafRef(0));
  c.push_back(Cell{});
  EXPECT_FALSE(ValidatePool(c.data(), 4, 3, false, 1).ok());
  // Depth mismatch: leaves expected one level higher.
  EXPECT_FALSE(ValidatePool(Chain(MakeLeafRef(0)).data(), 3, 2, false, 1).ok());
  EXPECT_FALSE(ValidatePool(nullptr, 0, 3, false, 1).ok());
}

// The brick a record of `cells` (a BuildCells pool) and `attrs` decodes to.
StatusOr<std::shared_ptr<DecodedBrick>> EncodeAndDecode(const std::vector<Cell>& cells,
                                                       const std::vector<VoxelAttributes>& attrs,
                                                       int depth, uint8_t flags) {
  const std::string raw = EncodeBrickRaw(cells, attrs, depth, flags);
  BrickEntry e;
  e.num_cells = uint32_t(cells.size());
  e.voxel_count = uint32_t(attrs.size());
  return DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e, depth, flags);
}

// Rewrites the top block of a store's index (same size), with valid CRCs.
std::string WithTop(const std::string& index, const std::vector<Cell>& top) {
  const uint8_t* p = reinterpret_cast<const uint8_t*>(index.data());
  auto f = DecodeFooter(p + index.size() - kFooterSize, "x");
  EXPECT_TRUE(f.ok());
  std::string out = index;
  EXPECT_EQ(f->top.size, top.size() * sizeof(Cell));
  std::memcpy(out.data() + f->top.offset, top.data(), f->top.size);
  std::string t = BlockTrailer(out.data() + f->top.offset, f->top.size, kCodecRaw);
  std::memcpy(out.data() + f->top.offset + f->top.size, t.data(), t.size());
  return out;
}

// The build-form top block of a store's index.
std::vector<Cell> TopOf(const std::string& index) {
  auto f = DecodeFooter(reinterpret_cast<const uint8_t*>(index.data()) + index.size() - kFooterSize,
                        "x");
  EXPECT_TRUE(f.ok());
  std::vector<Cell> top(f->top.size / sizeof(Cell));
  std::memcpy(top.data(), index.data() + f->top.offset, top.size() * sizeof(Cell));
  return top;
}

TEST(TopValidation, BadTopWithValidChecksumsIsRefusedAtOpen) {
  auto vol = GenerateShape("sphere:32");
  ASSERT_TRUE(vol.ok());
  StoreMeta meta = storage_test::MetaFor(vol->levels, 3, GridClass::kLevelSet, false);
  storage_test::TempDir tmp;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp / "s", vol->voxels, meta).ok());
  std::string index = storage_test::ReadFile(tmp / "s/index.vxi");
  std::string bricks = storage_test::ReadFile(tmp / "s/bricks.vxb");
  auto s = Store::Open(tmp / "s", {});
  ASSERT_TRUE(s.ok());
  OctreeView v = (*s)->view();
  std::vector<Cell> top = TopOf(index);
  const uint32_t bricks_n = uint32_t((*s)->meta().brick_count);
  auto open = [&](const std::vector<Cell>& t) {
    return OpenStoreFromFiles("mem", NewMemoryFile("mem/index.vxi", WithTop(index, t)),
                              NewMemoryFile("mem/bricks.vxb", bricks), {});
  };
  ASSERT_TRUE(open(top).ok());
  // Find a brick ref and a cell ref to damage.
  size_t bi = 0, bd = 0, ci = 0, cd = 0;
  bool found_b = false, found_c = false;
  for (size_t i = 0; i < top.size(); ++i)
    for (int d = 0; d < 8; ++d) {
      NodeRef r = top[i].child[d];
      if (r == kEmptyRef) continue;
      if (IsBrickRef(r) && !found_b) bi = i, bd = d, found_b = true;
      if (!IsBrickRef(r) && !found_c) ci = i, cd = d, found_c = true;
    }
  ASSERT_TRUE(found_b && found_c);
  for (NodeRef bad : {MakeBrickRef(bricks_n), MakeBrickRef(0x7fffffff), NodeRef(1), NodeRef(0x7fffffff)}) {
    auto t = top;
    t[bi].child[bd] = bad;
    auto r = open(t);
    EXPECT_EQ(r.status().code(), StatusCode::kCorruption) << std::hex << bad;
    EXPECT_NE(r.status().message().find("top"), std::string::npos) << r.status().ToString();
  }
  for (NodeRef bad : {NodeRef(0), NodeRef(v.top_cells), NodeRef(0x7fffffff), MakeBrickRef(0)}) {
    auto t = top;
    t[ci].child[cd] = bad;
    auto r = open(t);
    EXPECT_FALSE(r.ok()) << std::hex << bad;
  }
}

// Brick ids must be consecutive in the top's level order (Morton order):
// a top with two brick refs swapped is valid pre-order but refused.
TEST(TopValidation, NonConsecutiveBrickRefsAreRefusedAtOpen) {
  auto vol = GenerateShape("sphere:32");
  ASSERT_TRUE(vol.ok());
  StoreMeta meta = storage_test::MetaFor(vol->levels, 3, GridClass::kLevelSet, false);
  storage_test::TempDir tmp;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp / "s", vol->voxels, meta).ok());
  std::string index = storage_test::ReadFile(tmp / "s/index.vxi");
  std::string bricks = storage_test::ReadFile(tmp / "s/bricks.vxb");
  std::vector<Cell> top = TopOf(index);
  std::vector<NodeRef*> refs;
  for (Cell& c : top)
    for (NodeRef& r : c.child)
      if (IsBrickRef(r)) refs.push_back(&r);
  ASSERT_GT(refs.size(), 2u);
  std::swap(*refs[1], *refs[refs.size() - 2]);
  auto r = OpenStoreFromFiles("mem", NewMemoryFile("mem/index.vxi", WithTop(index, top)),
                              NewMemoryFile("mem/bricks.vxb", bricks), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCorruption);
  EXPECT_NE(r.status().message().find("mem/index.vxi"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("Morton"), std::string::npos) << r.status().message();
}

// Decoding undoes the delta coding while regrouping the raw record's planes
// into value arrays (UndeltaPlanes): every attribute combination and voxel
// count (SSE2 blocks of 8 and 16 and their tails) gives back WriteAttributes'
// bytes as PlanesToValues regroups them, and each voxel's attributes.
TEST(BrickDecoder, DecodedValuesAreTheWrittenAttributes) {
  auto vol = GenerateShape("noise:32");
  ASSERT_TRUE(vol.ok());
  const int depth = vol->levels;
  std::vector<LeafPoint> all = vol->voxels;
  std::sort(all.begin(), all.end(), MortonLess);
  all.erase(std::unique(all.begin(), all.end(), [](auto& a, auto& b) {
              return a.x == b.x && a.y == b.y && a.z == b.z;
            }), all.end());
  ASSERT_GT(all.size(), 40u);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (size_t n : {size_t(1), size_t(7), size_t(8), size_t(9), size_t(23), size_t(33), all.size()}) {
    std::vector<LeafPoint> pts(all.begin(), all.begin() + n);
    for (size_t i = 0; i < n; ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
    auto cells = BuildCells(pts, depth);
    std::vector<VoxelAttributes> attrs(n);
    for (VoxelAttributes& a : attrs) {
      a.normal = glm::vec3(u(rng), u(rng), u(rng));
      a.density = u(rng) * 100;
      a.color = glm::vec3(u(rng), u(rng), u(rng)) * 4.f;
      a.coverage = std::fabs(u(rng));
      a.temperature = 1000.f + 500.f * u(rng);
    }
    for (uint8_t flags = 1; flags <= kAttrAll; ++flags) {
      std::string raw = EncodeBrickRaw(cells, attrs, depth, flags);
      std::string planes;
      WriteAttributes(attrs, flags, &planes);
      const std::vector<uint8_t> expect = PlanesToValues(
          {reinterpret_cast<const uint8_t*>(planes.data()), planes.size()}, uint32_t(n), flags);
      BrickEntry e;
      e.num_cells = uint32_t(cells.size());
      e.voxel_count = uint32_t(n);
      auto d = DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e,
                              depth, flags);
      ASSERT_TRUE(d.ok()) << d.status().ToString();
      ASSERT_EQ((*d)->attr_values.size(), expect.size()) << n << " voxels, flags " << int(flags);
      EXPECT_EQ(0, std::memcmp((*d)->attr_values.data(), expect.data(), expect.size()))
          << n << " voxels, flags " << int(flags);
      for (size_t i = 0; i < n; ++i) {
        const VoxelAttributes a = ReadAttributes((*d)->attr_values.data(), uint32_t(n), flags, uint32_t(i));
        if (flags & kAttrNormal) {
          EXPECT_LT(glm::length(a.normal - glm::normalize(attrs[i].normal)), 1e-3f) << i;
        }
        if (flags & kAttrDensity) {
          EXPECT_EQ(a.density, attrs[i].density) << i;
          EXPECT_EQ(ReadDensity((*d)->attr_values.data(), uint32_t(n), flags, uint32_t(i)), attrs[i].density);
        }
        if (flags & kAttrColor) {
          EXPECT_LT(glm::length(a.color - attrs[i].color), 4e-3f) << i;
        }
        if (flags & kAttrCoverage) {
          EXPECT_NEAR(a.coverage, attrs[i].coverage, 1e-4f) << i;
        }
        if (flags & kAttrTemperature) {
          EXPECT_EQ(a.temperature, attrs[i].temperature) << i;
        }
      }
    }
  }
}

// Blocks of one density (DecodedBrick::uniform_density, uniform_levels),
// found when a brick is decoded: a full brick of one density is one block,
// and a voxel that differs in any byte of its density breaks its 2^3 block
// (and the whole brick's) but not the others.
TEST(BrickDecoder, FindsBlocksOfOneDensity) {
  const int depth = 2;  // 4^3 voxels, leaf cells of 2^3
  std::vector<LeafPoint> pts;
  for (uint64_t z = 0; z < 4; ++z)
    for (uint64_t y = 0; y < 4; ++y)
      for (uint64_t x = 0; x < 4; ++x) pts.push_back(LeafPoint{x, y, z, kEmptyRef});
  std::sort(pts.begin(), pts.end(), MortonLess);
  for (size_t i = 0; i < pts.size(); ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
  const auto cells = BuildCells(pts, depth);
  for (float other : {0.5f, std::nextafter(0.5f, 1.0f), 2.0f}) {
    for (uint32_t odd : {0u, 37u, 63u}) {
      std::vector<VoxelAttributes> attrs(pts.size());
      for (VoxelAttributes& a : attrs) a.density = 0.5f;
      attrs[odd].density = other;
      const std::string raw = EncodeBrickRaw(cells, attrs, depth, kAttrDensity);
      BrickEntry e;
      e.num_cells = uint32_t(cells.size());
      e.voxel_count = uint32_t(pts.size());
      auto d = DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e, depth,
                              kAttrDensity);
      ASSERT_TRUE(d.ok()) << d.status().ToString();
      const DecodedBrick& b = **d;
      if (other == 0.5f) {
        EXPECT_EQ(b.uniform_density, 0.5f);
        EXPECT_TRUE(b.uniform_levels.empty());
        continue;
      }
      EXPECT_LT(b.uniform_density, 0.0f) << other << " at " << odd;
      ASSERT_EQ(b.uniform_levels.size(), (pts.size() + 1) / 2);  // (half a byte a voxel)
      for (uint32_t i = 0; i < pts.size(); ++i)  // payloads of one leaf cell are 8 in a row
        EXPECT_EQ(b.UniformLevelsOf(i), i / 8 == odd / 8 ? -1 : 1)
            << other << " at " << odd << ", voxel " << i;
    }
  }
}

// A brick of densities mostly of one value, with a rim of other values (the
// inside of a fog beside its rim), keeps that value once and a bit per
// voxel (DecodedBrick::common) and reads back every voxel's density and
// attributes; a brick where fewer than half the voxels share it, or with a
// second attribute, keeps the plain value arrays.
TEST(BrickDecoder, KeepsTheCommonDensityOnce) {
  const int depth = 4;  // 16^3
  std::vector<LeafPoint> pts;
  for (uint64_t z = 0; z < 16; ++z)
    for (uint64_t y = 0; y < 16; ++y)
      for (uint64_t x = 0; x < 16; ++x)
        if (x + y + z < 36) pts.push_back(LeafPoint{x, y, z, kEmptyRef});  // a corner cut off
  std::sort(pts.begin(), pts.end(), MortonLess);
  for (size_t i = 0; i < pts.size(); ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
  const auto cells = BuildCells(pts, depth);
  // rim: the voxels with x + y + z >= rim_from get their own densities
  for (uint64_t rim_from : {uint64_t(30), uint64_t(12)}) {
    for (uint8_t flags : {uint8_t(kAttrDensity), uint8_t(kAttrDensity | kAttrTemperature)}) {
      std::vector<VoxelAttributes> attrs(pts.size());
      size_t rim = 0;
      for (size_t i = 0; i < pts.size(); ++i) {
        const uint64_t sum = pts[i].x + pts[i].y + pts[i].z;
        attrs[i].density = sum >= rim_from ? 0.001f * float(i + 1) : 1.0f;
        attrs[i].temperature = 300.0f;
        rim += sum >= rim_from;
      }
      auto d = EncodeAndDecode(cells, attrs, depth, flags);
      ASSERT_TRUE(d.ok()) << d.status().ToString();
      const DecodedBrick& b = **d;
      const bool expect_common = flags == kAttrDensity && 2 * rim <= pts.size();
      ASSERT_EQ(2 * rim <= pts.size(), rim_from == 30) << rim;  // (both forms are tried)
      EXPECT_EQ(b.common, expect_common) << "rim from " << rim_from << ", flags " << int(flags);
      if (expect_common) {
        EXPECT_EQ(b.common_density, 1.0f);
        EXPECT_EQ(b.attr_values.size(), 4 * rim);
        EXPECT_EQ(b.common_words.size(), (pts.size() + 63) / 64);
      } else {
        EXPECT_EQ(b.attr_values.size(), pts.size() * AttrBytesPerVoxel(flags));
      }
      for (uint32_t i = 0; i < pts.size(); ++i) {
        ASSERT_EQ(b.DensityOf(i), attrs[i].density) << "voxel " << i << ", rim from " << rim_from;
        const VoxelAttributes a = b.AttributesOf(i);
        ASSERT_EQ(a.density, attrs[i].density) << "voxel " << i;
        if (flags & kAttrTemperature) {
          ASSERT_EQ(a.temperature, 300.0f) << "voxel " << i;
        }
        // (a common voxel has no place of its own)
        EXPECT_EQ(b.DensityPlace(i) == nullptr, b.common && attrs[i].density == 1.0f) << "voxel " << i;
      }
      // Each voxel's block of one density (half a byte a voxel, cells of 8
      // starting at odd payloads too), against a search: the voxel's
      // aligned block of 2^L is full and of one density, that of 2^(L+1) is
      // not (or is the brick).
      std::map<std::tuple<uint64_t, uint64_t, uint64_t>, float> at;
      for (size_t i = 0; i < pts.size(); ++i) at[{pts[i].x, pts[i].y, pts[i].z}] = attrs[i].density;
      auto uniform = [&](const LeafPoint& q, int l) {
        const uint64_t m = ~((uint64_t(1) << l) - 1), side = uint64_t(1) << l;
        const auto d0 = at.find({q.x & m, q.y & m, q.z & m});
        if (d0 == at.end()) return false;
        for (uint64_t z = 0; z < side; ++z)
          for (uint64_t y = 0; y < side; ++y)
            for (uint64_t x = 0; x < side; ++x) {
              const auto d = at.find({(q.x & m) + x, (q.y & m) + y, (q.z & m) + z});
              if (d == at.end() || d->second != d0->second) return false;
            }
        return true;
      };
      for (uint32_t i = 0; i < pts.size(); i += 7) {
        const int l = b.UniformLevelsOf(i);
        if (l < 0) {
          ASSERT_FALSE(uniform(pts[i], 1)) << "voxel " << i;
          continue;
        }
        ASSERT_TRUE(uniform(pts[i], l)) << "voxel " << i << ", levels " << l;
        if (l < depth) {
          ASSERT_FALSE(uniform(pts[i], l + 1)) << "voxel " << i << ", levels " << l;
        }
      }
    }
  }
}

// A full brick whose voxels all have one value (the inside of a fog) decodes
// to the shared full pool and one voxel's attributes, and reads back as the
// brick it encodes: every payload's attributes, the pool LevelOrderPool
// makes. One voxel that differs in any attribute keeps the whole brick.
TEST(BrickDecoder, FullBrickOfOneValueSharesThePool) {
  for (int depth = 1; depth <= 3; ++depth) {
    const uint64_t side = uint64_t(1) << depth;
    std::vector<LeafPoint> pts;
    for (uint64_t z = 0; z < side; ++z)
      for (uint64_t y = 0; y < side; ++y)
        for (uint64_t x = 0; x < side; ++x) pts.push_back(LeafPoint{x, y, z, kEmptyRef});
    std::sort(pts.begin(), pts.end(), MortonLess);
    for (size_t i = 0; i < pts.size(); ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
    const auto cells = BuildCells(pts, depth);
    const auto expect_pool = LevelOrderPool(cells, depth, false);
    ASSERT_TRUE(expect_pool.ok());
    const uint8_t flags = kAttrDensity | kAttrTemperature | kAttrColor;
    for (int odd : {-1, 0, int(pts.size()) - 1}) {
      std::vector<VoxelAttributes> attrs(pts.size());
      for (VoxelAttributes& a : attrs) {
        a.density = 0.75f;
        a.temperature = 1500.0f;
        a.color = glm::vec3(0.25f, 0.5f, 1.0f);
      }
      if (odd >= 0) attrs[size_t(odd)].temperature = 1501.0f;
      auto d = EncodeAndDecode(cells, attrs, depth, flags);
      ASSERT_TRUE(d.ok()) << d.status().ToString();
      const DecodedBrick& b = **d;
      EXPECT_EQ(b.full_of_one, odd < 0) << "depth " << depth << ", odd " << odd;
      EXPECT_EQ(b.uniform_density, 0.75f);  // (temperature does not break a block of one density)
      ASSERT_EQ(b.CellCount(), expect_pool->size());
      EXPECT_EQ(0, std::memcmp(b.CellData(), expect_pool->data(), expect_pool->size() * sizeof(CompactCell)));
      EXPECT_TRUE(ValidateLevelOrderPool(b.CellData(), b.CellCount(), depth, pts.size()).ok());
      if (odd < 0) {
        EXPECT_EQ(b.attr_values.size(), AttrBytesPerVoxel(flags));
      }
      for (uint32_t i = 0; i < pts.size(); ++i) {
        const VoxelAttributes a = ReadAttributes(b.attr_values.data(), b.AttrCount(), flags, b.AttrIndex(i));
        EXPECT_EQ(a.density, attrs[i].density);
        EXPECT_EQ(a.temperature, attrs[i].temperature) << "voxel " << i;
        EXPECT_EQ(a.color, glm::vec3(0.25f, 0.5f, 1.0f));
      }
    }
  }
  // A full brick deeper than the shared pools decodes as any other.
  EXPECT_TRUE(FullPool(kMaxFullPoolDepth + 1).empty());
  EXPECT_EQ(FullPool(kMaxFullPoolDepth).size(), (size_t(1) << (3 * kMaxFullPoolDepth)) / 7);
}

// The byte scan full bricks are recognised by: one differing byte anywhere
// (in the wide steps, between them, in the tail) is found.
TEST(BrickDecoder, AllBytesAreFindsAnyDifferingByte) {
  for (size_t n : {size_t(0), size_t(1), size_t(7), size_t(63), size_t(64), size_t(65), size_t(200)})
    for (uint8_t byte : {uint8_t(0), uint8_t(0xff), uint8_t(0x5a)}) {
      std::vector<uint8_t> v(n + 1, byte);
      v[n] = uint8_t(~byte);  // past the end: never read
      EXPECT_TRUE(AllBytesAre(v.data(), n, byte)) << n;
      for (size_t i = 0; i < n; ++i) {
        for (uint8_t flip : {uint8_t(1), uint8_t(0x80)}) {
          v[i] = uint8_t(byte ^ flip);
          EXPECT_FALSE(AllBytesAre(v.data(), n, byte)) << "n " << n << ", byte " << i;
          v[i] = byte;
        }
      }
    }
}

TEST(BrickDecoder, MutatedBricksNeverYieldABadPool) {
  auto vol = GenerateShape("noise:32");
  ASSERT_TRUE(vol.ok());
  std::vector<LeafPoint> pts;
  for (const LeafPoint& p : vol->voxels)
    if (p.x < 16 && p.y < 16 && p.z < 16) pts.push_back(p);
  std::sort(pts.begin(), pts.end(), MortonLess);
  pts.erase(std::unique(pts.begin(), pts.end(), [](auto& a, auto& b) {
              return a.x == b.x && a.y == b.y && a.z == b.z;
            }), pts.end());
  ASSERT_GT(pts.size(), 20u);
  for (size_t i = 0; i < pts.size(); ++i) pts[i].ref = MakeLeafRef(uint32_t(i));
  auto cells = BuildCells(pts, 4);
  std::vector<VoxelAttributes> attrs(pts.size());
  const uint8_t flags = kAttrNormal | kAttrColor;
  std::string raw = EncodeBrickRaw(cells, attrs, 4, flags);
  BrickEntry e;
  e.num_cells = uint32_t(cells.size());
  e.voxel_count = uint32_t(pts.size());
  auto good = DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e, 4, flags);
  ASSERT_TRUE(good.ok()) << good.status().ToString();
  ASSERT_EQ((*good)->cells.size(), cells.size());
  auto expect = LevelOrderPool(cells, 4, false);
  ASSERT_TRUE(expect.ok());
  EXPECT_EQ(0, std::memcmp((*good)->cells.data(), expect->data(), cells.size() * sizeof(CompactCell)));
  EXPECT_TRUE(ValidateLevelOrderPool((*good)->cells.data(), cells.size(), 4, pts.size()).ok());
  // Wrong depth, flags or counts are refused.
  EXPECT_FALSE(DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e, 5, flags).ok());
  EXPECT_FALSE(DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), e, 4, 0).ok());
  EXPECT_FALSE(DecodeBrickRaw(reinterpret_cast<const uint8_t*>(raw.data()), raw.size() - 1, e, 4, flags).ok());
  std::mt19937_64 rng(11);
  int accepted = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::string m = raw;
    // Mutate 1-3 bytes of the header and topology (attributes always decode).
    int k = 1 + int(rng() % 3);
    for (int j = 0; j < k; ++j) m[rng() % (kBrickHeaderSize + cells.size())] ^= char(1 + rng() % 255);
    BrickEntry me = e;
    me.num_cells = DecodeFixed32Raw(m.data());
    me.voxel_count = DecodeFixed32Raw(m.data() + 4);
    auto d = DecodeBrickRaw(reinterpret_cast<const uint8_t*>(m.data()), m.size(), me, 4, flags);
    if (!d.ok()) {
      EXPECT_EQ(d.status().code(), StatusCode::kCorruption);
      continue;
    }
    ++accepted;
    ASSERT_TRUE(ValidateLevelOrderPool((*d)->cells.data(), (*d)->cells.size(), 4,
                                       (*d)->voxel_count).ok());
    ASSERT_EQ((*d)->attr_values.size(), size_t((*d)->voxel_count) * AttrBytesPerVoxel(flags));
  }
  SUCCEED() << accepted << " mutated bricks decoded to valid pools";
}

}  // namespace
}  // namespace vox

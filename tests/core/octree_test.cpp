// MortonLess against an explicit interleaved key, BuildCells and
// MemoryOctree against a walk of their cells, bad input to Build and
// Tracer::Create, brick payloads of hits, and brick fetch errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "core/octree.h"
#include "core/tracer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

using Key = unsigned __int128;

// Bit 3i of the key is bit i of x, 3i+1 of y, 3i+2 of z (40 bits each).
Key MortonKey(const LeafPoint& p) {
  Key k = 0;
  for (int i = 0; i < 40; ++i) {
    k |= Key((p.x >> i) & 1) << (3 * i);
    k |= Key((p.y >> i) & 1) << (3 * i + 1);
    k |= Key((p.z >> i) & 1) << (3 * i + 2);
  }
  return k;
}

LeafPoint RandomPoint(Rng& rng, int levels) {
  const uint64_t mask = (uint64_t(1) << levels) - 1;
  return {rng.Bits() & mask, rng.Bits() & mask, rng.Bits() & mask, kEmptyRef};
}

TEST(Octree, MortonLessMatchesInterleavedKey) {
  Rng rng(1);
  for (int i = 0; i < 200000; ++i) {
    const int levels = int(rng.Int(1, 40));
    LeafPoint a = RandomPoint(rng, levels), b = RandomPoint(rng, levels);
    if (i % 4 == 1) b = a;  // equal
    if (i % 4 == 2) {       // a shared prefix: differ only in a few low bits
      b = a;
      const int low = int(rng.Int(0, levels - 1));
      b.x ^= rng.Bits() & ((uint64_t(1) << low) - 1);
      b.z ^= rng.Bits() & ((uint64_t(1) << low) - 1);
    }
    ASSERT_EQ(MortonLess(a, b), MortonKey(a) < MortonKey(b))
        << a.x << "," << a.y << "," << a.z << " vs " << b.x << "," << b.y << "," << b.z;
  }
}

// Walks `cells` from the root to the last level along `p`; returns the
// reference found there, or kEmptyRef if an empty octant stops the walk.
NodeRef Walk(const std::vector<Cell>& cells, int levels, const LeafPoint& p) {
  uint32_t cell = 0;
  for (int bit = levels - 1; bit >= 0; --bit) {
    unsigned digit = unsigned((p.x >> bit) & 1) | unsigned(((p.y >> bit) & 1) << 1) |
                     unsigned(((p.z >> bit) & 1) << 2);
    NodeRef r = cells[cell].child[digit];
    if (r == kEmptyRef || bit == 0) return r;
    EXPECT_FALSE(IsBrickRef(r));
    EXPECT_LT(r, cells.size());
    cell = r;
  }
  return kEmptyRef;
}

TEST(Octree, BuildCellsHoldsExactlyThePoints) {
  Rng rng(2);
  for (int levels : {1, 3, 7, 20, 40}) {
    std::set<std::tuple<uint64_t, uint64_t, uint64_t>> seen;
    std::vector<LeafPoint> pts;
    const size_t want = levels == 1 ? 5 : (levels == 3 ? 300 : 3000);  // 2^3 grid: 512 voxels
    while (pts.size() < want) {
      LeafPoint p = RandomPoint(rng, levels);
      if (levels > 7 && rng.Chance(0.5) && !pts.empty()) {  // clusters
        p = pts[size_t(rng.Int(0, int64_t(pts.size()) - 1))];
        p.x ^= uint64_t(rng.Int(1, 7));
      }
      if (!seen.insert({p.x, p.y, p.z}).second) continue;
      p.ref = MakeLeafRef(uint32_t(pts.size()));
      pts.push_back(p);
    }
    std::sort(pts.begin(), pts.end(), MortonLess);
    std::vector<Cell> cells = BuildCells(pts, levels);
    // One cell per occupied octant of levels 1..N.
    std::set<std::tuple<int, uint64_t, uint64_t, uint64_t>> octants;
    for (const LeafPoint& p : pts)
      for (int k = 1; k <= levels; ++k) octants.insert({k, p.x >> k, p.y >> k, p.z >> k});
    EXPECT_EQ(cells.size(), octants.size()) << levels;
    for (const LeafPoint& p : pts) ASSERT_EQ(Walk(cells, levels, p), p.ref);
    for (int i = 0; i < 3000; ++i) {
      LeafPoint q = RandomPoint(rng, levels);
      NodeRef r = Walk(cells, levels, q);
      EXPECT_EQ(r != kEmptyRef, seen.count({q.x, q.y, q.z}) > 0);
    }
  }
  std::vector<Cell> empty = BuildCells({}, 5);
  ASSERT_EQ(empty.size(), 1u);
  for (NodeRef r : empty[0].child) EXPECT_EQ(r, kEmptyRef);
}

// Random pre-order pools: clustered, sparse and dense, leaves or bricks at
// the last level.
std::vector<Cell> RandomPool(Rng& rng, int levels, size_t want, bool bricks) {
  std::set<std::tuple<uint64_t, uint64_t, uint64_t>> seen;
  std::vector<LeafPoint> pts;
  const uint64_t cap = uint64_t(1) << std::min(3 * levels, 20);
  while (pts.size() < std::min<uint64_t>(want, cap / 2)) {
    LeafPoint p = RandomPoint(rng, levels);
    if (rng.Chance(0.6) && !pts.empty()) {
      p = pts[size_t(rng.Int(0, int64_t(pts.size()) - 1))];
      const uint64_t m = (uint64_t(1) << levels) - 1;
      p.x = (p.x ^ uint64_t(rng.Int(0, 3))) & m;
      p.z = (p.z ^ uint64_t(rng.Int(0, 1))) & m;
    }
    if (!seen.insert({p.x, p.y, p.z}).second) continue;
    pts.push_back(p);
  }
  std::sort(pts.begin(), pts.end(), MortonLess);
  for (size_t i = 0; i < pts.size(); ++i)
    pts[i].ref = bricks ? MakeBrickRef(uint32_t(i)) : MakeLeafRef(uint32_t(i));
  return BuildCells(pts, levels);
}

// Every child query of every cell, all 8 digits, answered by the level-order
// pool as by the pre-order pool it came from: walked side by side.
TEST(Octree, LevelOrderPoolAnswersLikeThePreOrderPool) {
  Rng rng(8);
  for (int trial = 0; trial < 60; ++trial) {
    const int levels = int(rng.Int(1, 9));
    const bool bricks = rng.Chance(0.5);
    std::vector<Cell> pre = RandomPool(rng, levels, size_t(rng.Int(0, 4000)), bricks);
    auto lo = LevelOrderPool(pre, levels, bricks);
    ASSERT_TRUE(lo.ok()) << lo.status().ToString();
    ASSERT_EQ(lo->size(), pre.size());
    // Breadth first over both: level order is the order cells are reached.
    std::vector<std::pair<uint32_t, uint32_t>> level{{0, 0}}, next;  // (pre, level-order)
    uint32_t expect_index = 1, visited = 0;
    for (int l = 0; l < levels; ++l) {
      next.clear();
      uint32_t expect_payload = 0;
      for (auto [pi, li] : level) {
        ++visited;
        ASSERT_LT(li, lo->size());
        const CompactCell c = (*lo)[li];
        for (unsigned d = 0; d < 8; ++d) {
          const NodeRef r = pre[pi].child[d];
          ASSERT_EQ(HasChild(c, d), r != kEmptyRef) << trial << " cell " << pi << " digit " << d;
          if (r == kEmptyRef) continue;
          const uint32_t ci = ChildIndex(c, d);
          if (l == levels - 1) {
            ASSERT_EQ(ci, bricks ? (r & kBrickIdMask) : LeafPayload(r));
            ASSERT_EQ(ci, expect_payload++);
          } else {
            ASSERT_EQ(ci, expect_index++);  // children contiguous, in level order
            next.push_back({r, ci});
          }
        }
      }
      level.swap(next);
    }
    EXPECT_EQ(visited, pre.size());
  }
  // The empty pool: one root with no children.
  auto empty = LevelOrderPool(BuildCells({}, 4), 4, false);
  ASSERT_TRUE(empty.ok());
  ASSERT_EQ(empty->size(), 1u);
  EXPECT_EQ(ChildMask((*empty)[0]), 0u);
}

// A compact cell's child index counts the mask's bits below the digit: by
// POPCNT on x86-64-v2 builds, by table on the baseline; either against
// counting bit by bit, for every mask and digit.
TEST(Octree, ChildIndexCountsTheBitsBelowTheDigit) {
  for (uint32_t mask = 0; mask < 256; ++mask) {
    uint32_t bits = 0;
    for (int i = 0; i < 8; ++i) bits += (mask >> i) & 1u;
    ASSERT_EQ(Popcount8(mask), bits) << mask;
    ASSERT_EQ(Popcount8(mask | 0xa500u), bits) << "only the low 8 bits count, " << mask;
    uint32_t below = 0;
    for (unsigned d = 0; d < 8; ++d) {
      const CompactCell c = MakeCompactCell(1000, mask);
      if (HasChild(c, d)) {
        EXPECT_EQ(ChildIndex(c, d), 1000 + below) << mask << " digit " << d;
      }
      below += (mask >> d) & 1u;
    }
  }
}

TEST(Octree, LevelOrderPoolRefusesNonConsecutiveLastLevelRefs) {
  Rng rng(9);
  std::vector<Cell> pre = RandomPool(rng, 5, 500, true);
  ASSERT_TRUE(LevelOrderPool(pre, 5, true).ok());
  // Swap two brick refs: each still in range, but no longer in Morton order.
  std::vector<std::pair<size_t, int>> refs;
  for (size_t i = 0; i < pre.size(); ++i)
    for (int d = 0; d < 8; ++d)
      if (IsBrickRef(pre[i].child[d])) refs.push_back({i, d});
  ASSERT_GT(refs.size(), 2u);
  auto swapped = pre;
  std::swap(swapped[refs[0].first].child[refs[0].second],
            swapped[refs.back().first].child[refs.back().second]);
  auto r = LevelOrderPool(swapped, 5, true);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCorruption);
  EXPECT_NE(r.status().message().find("Morton"), std::string::npos) << r.status().message();
  // Leaf refs where brick refs belong, and the reverse.
  EXPECT_FALSE(LevelOrderPool(pre, 5, false).ok());
  // A cell reached twice.
  auto twice = pre;
  for (int d = 0; d < 8; ++d)
    if (twice[0].child[d] != kEmptyRef) {
      for (int e = 0; e < 8; ++e) twice[0].child[e] = twice[0].child[d];
      break;
    }
  EXPECT_FALSE(LevelOrderPool(twice, 5, true).ok());
}

TEST(Octree, MemoryOctreeRefusesBadInput) {
  std::vector<LeafPoint> v = {{1, 2, 3, kEmptyRef}};
  for (auto [levels, bl] : {std::pair{0, 1}, {41, 10}, {5, 0}, {5, 6}}) {
    auto t = MemoryOctree::Build(v, levels, bl);
    ASSERT_FALSE(t.ok()) << levels << " " << bl;
    EXPECT_EQ(t.status().code(), StatusCode::kInvalidArgument);
  }
  auto outside = MemoryOctree::Build({{1, 2, 32, kEmptyRef}}, 5, 3);
  ASSERT_FALSE(outside.ok());
  EXPECT_EQ(outside.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(outside.status().message().find("(1,2,32)"), std::string::npos)
      << outside.status().message();
  auto ok = MemoryOctree::Build(v, 5, 3);
  ASSERT_TRUE(ok.ok());
  auto bad = (*ok)->FetchBrick(uint32_t((*ok)->num_bricks()));
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kCorruption);
}

TEST(Octree, MemoryOctreeBricksHoldEveryVoxel) {
  Rng rng(3);
  for (auto [levels, bl] : {std::pair{6, 6}, {6, 3}, {6, 1}, {12, 5}, {40, 20}, {40, 37}}) {
    std::vector<Voxel> vox = levels <= 12 ? RandomVoxels(rng, 2000, {0, 0, 0}, int64_t(1) << levels)
                                          : RandomVoxels(rng, 2000, {int64_t(1) << 39, 77, 5}, 64);
    std::vector<LeafPoint> pts = ToLeafPoints(vox);
    pts.insert(pts.end(), pts.begin(), pts.begin() + 100);  // duplicates are merged
    auto built = MemoryOctree::Build(pts, levels, bl);
    ASSERT_TRUE(built.ok()) << built.status().ToString();
    MemoryOctree& t = **built;
    ASSERT_EQ(t.voxels().size(), vox.size());
    EXPECT_TRUE(std::is_sorted(t.voxels().begin(), t.voxels().end(), MortonLess));
    const int sub = levels - bl;
    std::set<std::tuple<uint64_t, uint64_t, uint64_t>> brick_octants;
    for (const LeafPoint& p : t.voxels()) brick_octants.insert({p.x >> sub, p.y >> sub, p.z >> sub});
    EXPECT_EQ(t.num_bricks(), bl == levels ? 0u : brick_octants.size());
    // Walk top then brick to every voxel; its payload maps back to it.
    for (size_t i = 0; i < t.voxels().size(); ++i) {
      const LeafPoint& p = t.voxels()[i];
      const OctreeView v = t.view();
      const CompactCell* pool = v.top;
      uint32_t cell = 0, brick = kNoBrick;
      ChildRef r;
      for (int level = 0; level < levels; ++level) {
        const int bit = levels - 1 - level;
        unsigned digit = unsigned((p.x >> bit) & 1) | unsigned(((p.y >> bit) & 1) << 1) |
                         unsigned(((p.z >> bit) & 1) << 2);
        r = ChildOf(pool[cell], digit, level, v);
        ASSERT_NE(r.kind, ChildRef::kEmpty);
        if (r.kind == ChildRef::kPayload) break;
        if (r.kind == ChildRef::kBrick) {
          ASSERT_EQ(bit, sub) << "brick reference away from the brick level";
          brick = r.index;
          auto b = t.FetchBrick(brick);
          ASSERT_TRUE(b.ok());
          pool = b->cells;
          cell = 0;
        } else {
          ASSERT_LT(r.index, pool == v.top ? v.top_cells : t.FetchBrick(brick)->num_cells);
          cell = r.index;
        }
      }
      ASSERT_EQ(r.kind, ChildRef::kPayload);
      ASSERT_EQ(t.VoxelIndex(brick, r.index), i);
    }
  }
}

TEST(Octree, HitsCarryTheirBrickAndPayload) {
  Rng rng(4);
  std::vector<Voxel> vox = DenseVoxels(rng, 0.2, {0, 0, 0}, 64);
  for (int bl : {6, 4, 2}) {
    auto built = MemoryOctree::Build(ToLeafPoints(vox), 6, bl);
    ASSERT_TRUE(built.ok());
    for (int n1 : {6, 3, 1}) {
      auto tr = DefaultTracer::Create((*built)->view(), n1);
      ASSERT_TRUE(tr.ok());
      for (int i = 0; i < 300; ++i) {
        Ray r = RayFrom(rng, glm::dvec3(rng.Uniform(0, 64), rng.Uniform(0, 64), rng.Uniform(0, 64)));
        int visits = 0;
        Status s = tr->Traverse(r, [&](const Hit& h) {
          const LeafPoint& p = (*built)->voxels()[(*built)->VoxelIndex(h.brick, h.payload)];
          EXPECT_EQ(Voxel({int64_t(p.x), int64_t(p.y), int64_t(p.z)}), ToVoxel(h));
          EXPECT_EQ(h.brick == kNoBrick, bl == 6);
          return ++visits < 5;  // stopping early ends the traversal
        });
        ASSERT_TRUE(s.ok());
        EXPECT_LE(visits, 5);
      }
    }
  }
}

class FailingSource : public BrickSource {
 public:
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    return IoError("brick " + std::to_string(id) + " of test.vox: read failed");
  }
};

TEST(Octree, BrickErrorsReachTheCaller) {
  Rng rng(5);
  auto built = MemoryOctree::Build(ToLeafPoints(DenseVoxels(rng, 0.3, {0, 0, 0}, 64)), 6, 2);
  ASSERT_TRUE(built.ok());
  const Ray ray{{32.5, 32.5, -3}, {0.01, 0.02, 1}};
  FailingSource failing;
  OctreeView view = (*built)->view();
  view.bricks = &failing;
  for (int n1 : {6, 1, 3}) {
    auto tr = DefaultTracer::Create(view, n1);
    ASSERT_TRUE(tr.ok());
    auto h = tr->FirstHit(ray);
    ASSERT_FALSE(h.ok());
    EXPECT_EQ(h.status().code(), StatusCode::kIoError);
    EXPECT_NE(h.status().message().find("test.vox"), std::string::npos);
  }
  view.bricks = nullptr;
  auto tr = DefaultTracer::Create(view, 3);
  ASSERT_TRUE(tr.ok());
  auto h = tr->FirstHit(ray);
  ASSERT_FALSE(h.ok());
  EXPECT_EQ(h.status().code(), StatusCode::kCorruption);
}

// A one-thread source that keeps what it lends in a small table (as the
// renderer's per-thread table does); id 1000 or above fails.
class LendingSource : public BrickSource {
 public:
  explicit LendingSource(BrickSource* base) : base_(base) {}
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    ++fetches;
    return base_->FetchBrick(id);
  }
  bool lends() const override { return true; }
  const BrickView* LendBrick(uint32_t id, Status* error) override {
    ++lends_count;
    if (fail) {
      *error = IoError("brick " + std::to_string(id) + " of lent.vox: read failed");
      return nullptr;
    }
    Slot& s = slots_[id % 4];
    if (s.id != id || s.view.cells == nullptr) {
      auto v = base_->FetchBrick(id);
      if (!v.ok()) {
        *error = v.status();
        return nullptr;
      }
      s.id = id;
      s.view = *v;
    }
    return &s.view;
  }
  int fetches = 0, lends_count = 0;
  bool fail = false;

 private:
  struct Slot {
    uint32_t id = 0;
    BrickView view;
  };
  BrickSource* base_;
  Slot slots_[4];
};

TEST(Octree, LendingSourceTracesLikeFetching) {
  Rng rng(6);
  auto built = MemoryOctree::Build(ToLeafPoints(DenseVoxels(rng, 0.05, {0, 0, 0}, 64)), 6, 3);
  ASSERT_TRUE(built.ok());
  LendingSource lending((*built).get());
  OctreeView view = (*built)->view();
  view.bricks = &lending;
  for (int n1 : {6, 3, 2}) {
    auto tf = DefaultTracer::Create((*built)->view(), n1);
    auto tl = DefaultTracer::Create(view, n1);
    ASSERT_TRUE(tf.ok() && tl.ok());
    TraceCounters cf, cl;
    for (int i = 0; i < 300; ++i) {
      Ray r = RayFrom(rng, glm::dvec3(rng.Uniform(0, 64), rng.Uniform(0, 64), rng.Uniform(0, 64)));
      std::vector<Hit> hf, hl;
      ASSERT_TRUE(tf->Traverse(r, [&](const Hit& h) { hf.push_back(h); return hf.size() < 6; }, &cf).ok());
      ASSERT_TRUE(tl->Traverse(r, [&](const Hit& h) { hl.push_back(h); return hl.size() < 6; }, &cl).ok());
      ASSERT_EQ(hf.size(), hl.size());
      for (size_t k = 0; k < hf.size(); ++k) {
        EXPECT_EQ(ToVoxel(hf[k]), ToVoxel(hl[k]));
        EXPECT_EQ(hf[k].t, hl[k].t);
        EXPECT_EQ(hf[k].brick, hl[k].brick);
        EXPECT_EQ(hf[k].payload, hl[k].payload);
      }
    }
    EXPECT_EQ(cf.brick_fetches, cl.brick_fetches);
    if (n1 < 6) {
      EXPECT_GT(cl.brick_fetches, 0u);
    }
  }
  EXPECT_EQ(lending.fetches, 0);  // every brick was lent, none fetched
  EXPECT_GT(lending.lends_count, 0);
  lending.fail = true;
  auto tl = DefaultTracer::Create(view, 3);
  ASSERT_TRUE(tl.ok());
  bool failed = false;
  for (int i = 0; i < 50 && !failed; ++i) {
    Ray r = RayFrom(rng, glm::dvec3(rng.Uniform(0, 64), rng.Uniform(0, 64), rng.Uniform(0, 64)));
    auto h = tl->FirstHit(r);
    if (!h.ok()) {
      failed = true;
      EXPECT_EQ(h.status().code(), StatusCode::kIoError);
      EXPECT_NE(h.status().message().find("lent.vox"), std::string::npos);
    }
  }
  EXPECT_TRUE(failed);
}

TEST(Octree, TracerCreateRefusesBadSplits) {
  auto built = MemoryOctree::Build({{1, 2, 3, kEmptyRef}}, 30, 10);
  ASSERT_TRUE(built.ok());
  for (int n1 : {0, -1, 31, 9, 21}) {  // 9 leaves 21 levels for the second step
    auto tr = DefaultTracer::Create((*built)->view(), n1);
    ASSERT_FALSE(tr.ok()) << n1;
    EXPECT_EQ(tr.status().code(), StatusCode::kInvalidArgument);
  }
  EXPECT_TRUE(DefaultTracer::Create((*built)->view(), 10).ok());
  EXPECT_TRUE(DefaultTracer::Create((*built)->view(), 20).ok());
  OctreeView none;
  EXPECT_FALSE(DefaultTracer::Create(none, 1).ok());
}

}  // namespace
}  // namespace vox::testing

// LendingBrickTable against the source it fronts: it lends the very cells the
// source holds, fetches a brick again only after another took its slot, passes
// the source's errors through unchanged, and never pins more bricks than it
// has slots (counted by the source's own pins).
#include "storage/brick_table.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "core/octree.h"
#include "core/tracer.h"

namespace vox {
namespace {

// A MemoryOctree's bricks behind pins the test can count, failing on request.
class CountingSource : public BrickSource {
 public:
  explicit CountingSource(MemoryOctree* tree) : tree_(tree) {}
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    ++fetches;
    if (id == fail_id) return IoError("brick " + std::to_string(id) + " of 'test.bricks': bad crc");
    VOX_ASSIGN_OR_RETURN(BrickView v, tree_->FetchBrick(id));
    auto alive = alive_;
    ++*alive;
    // The pin keeps the tree's pin and counts itself until released.
    auto inner = v.pin;
    v.pin = std::shared_ptr<const void>(new int(0), [alive, inner](const void* p) {
      --*alive;
      delete static_cast<const int*>(p);
    });
    return v;
  }
  int live_pins() const { return *alive_; }
  uint32_t fail_id = kNoBrick;
  int fetches = 0;

 private:
  MemoryOctree* tree_;
  std::shared_ptr<std::atomic<int>> alive_ = std::make_shared<std::atomic<int>>(0);
};

std::unique_ptr<MemoryOctree> ManyBricks() {
  // Levels 7, bricks under level 4: one voxel per brick-level octant on a
  // sparse lattice gives a few hundred bricks.
  std::vector<LeafPoint> pts;
  for (uint64_t z = 0; z < 128; z += 16)
    for (uint64_t y = 0; y < 128; y += 16)
      for (uint64_t x = 0; x < 128; x += 16) pts.push_back({x + (y % 7), y, z + (x % 5), kEmptyRef});
  auto t = MemoryOctree::Build(pts, 7, 4);
  EXPECT_TRUE(t.ok()) << t.status().ToString();
  return std::move(t).value();
}

TEST(LendingBrickTable, LendsTheSourcesCells) {
  auto tree = ManyBricks();
  ASSERT_GT(tree->num_bricks(), 256u);
  CountingSource src(tree.get());
  LendingBrickTable table(&src, 4);
  EXPECT_TRUE(table.lends());
  std::mt19937 rng(7);
  for (int i = 0; i < 2000; ++i) {
    const uint32_t id = uint32_t(rng() % tree->num_bricks());
    Status error;
    const BrickView* v = table.LendBrick(id, &error);
    ASSERT_NE(v, nullptr) << error.ToString();
    auto truth = tree->FetchBrick(id);
    ASSERT_TRUE(truth.ok());
    ASSERT_EQ(v->num_cells, truth->num_cells) << "brick " << id;
    EXPECT_EQ(0, std::memcmp(v->cells, truth->cells, sizeof(CompactCell) * v->num_cells)) << id;
    EXPECT_EQ(v->data, truth->data);
    // FetchBrick hands out the same view, with a pin of its own.
    auto copy = table.FetchBrick(id);
    ASSERT_TRUE(copy.ok());
    EXPECT_EQ(copy->cells, v->cells);
    EXPECT_NE(copy->pin, nullptr);
  }
}

TEST(LendingBrickTable, RefetchesOnlyAfterItsSlotWasTaken) {
  auto tree = ManyBricks();
  CountingSource src(tree.get());
  LendingBrickTable table(&src, 8);
  Status error;
  ASSERT_NE(table.LendBrick(3, &error), nullptr);
  ASSERT_NE(table.LendBrick(3, &error), nullptr);
  ASSERT_NE(table.LendBrick(3, &error), nullptr);
  EXPECT_EQ(src.fetches, 1);
  // Lending every brick once more than there are slots must evict some
  // slot; every brick still reads correctly afterwards.
  for (uint32_t id = 0; id < tree->num_bricks(); ++id) ASSERT_NE(table.LendBrick(id, &error), nullptr);
  const int after_sweep = src.fetches;
  EXPECT_GE(after_sweep, int(tree->num_bricks()));  // brick 3 may have kept its slot
  EXPECT_LE(after_sweep, int(tree->num_bricks()) + 1);
}

TEST(LendingBrickTable, PropagatesErrorsAndDoesNotKeepThem) {
  auto tree = ManyBricks();
  CountingSource src(tree.get());
  src.fail_id = 5;
  LendingBrickTable table(&src, 4);
  Status error;
  EXPECT_EQ(table.LendBrick(5, &error), nullptr);
  EXPECT_EQ(error.code(), StatusCode::kIoError);
  EXPECT_NE(error.message().find("test.bricks"), std::string::npos) << error.ToString();
  auto f = table.FetchBrick(5);
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), StatusCode::kIoError);
  // The failure is not cached: the source is asked again, and succeeds.
  src.fail_id = kNoBrick;
  const int before = src.fetches;
  Status ok;
  const BrickView* v = table.LendBrick(5, &ok);
  ASSERT_NE(v, nullptr) << ok.ToString();
  EXPECT_EQ(src.fetches, before + 1);
  // A brick id the source does not have is the source's error too.
  Status missing;
  EXPECT_EQ(table.LendBrick(uint32_t(tree->num_bricks()) + 10, &missing), nullptr);
  EXPECT_FALSE(missing.ok());
}

TEST(LendingBrickTable, PinsAtMostItsSlots) {
  auto tree = ManyBricks();
  CountingSource src(tree.get());
  for (int bits : {1, 4, 6}) {
    {
      LendingBrickTable table(&src, bits);
      ASSERT_EQ(table.num_slots(), size_t(1) << bits);
      Status error;
      for (int round = 0; round < 3; ++round)
        for (uint32_t id = 0; id < tree->num_bricks(); ++id) {
          ASSERT_NE(table.LendBrick((id * 37 + round) % tree->num_bricks(), &error), nullptr);
          ASSERT_LE(src.live_pins(), int(table.num_slots())) << bits;
        }
      EXPECT_LE(table.pinned(), table.num_slots());
      EXPECT_EQ(int(table.pinned()), src.live_pins());
    }
    EXPECT_EQ(src.live_pins(), 0) << "the table released its pins";
  }
}

TEST(LendingBrickTable, SlotBitsFollowTheCacheBudget) {
  EXPECT_EQ(LendingBrickTable::SlotBits(0), 4);
  EXPECT_EQ(LendingBrickTable::SlotBits(uint64_t(64) << 20), 4);
  EXPECT_EQ(LendingBrickTable::SlotBits(uint64_t(1) << 30), 8);
  EXPECT_EQ(LendingBrickTable::SlotBits(uint64_t(1) << 40), 8);
  const int mid = LendingBrickTable::SlotBits(uint64_t(256) << 20);
  EXPECT_GT(mid, 4);
  EXPECT_LT(mid, 8);
}

// A MemoryOctree's bricks as copies whose memory is scrubbed (every cell
// emptied) when their last pin goes, as a cache that evicts and reuses
// memory would leave it. (The copies are kept, so reading a scrubbed one is
// a wrong answer, not undefined behaviour.)
class ScrubbingSource : public BrickSource {
 public:
  explicit ScrubbingSource(MemoryOctree* tree) : tree_(tree) {}
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    VOX_ASSIGN_OR_RETURN(BrickView v, tree_->FetchBrick(id));
    auto copy = std::make_shared<std::vector<CompactCell>>(v.cells, v.cells + v.num_cells);
    kept_.push_back(copy);
    v.cells = copy->data();
    v.pin = std::shared_ptr<const void>(copy.get(), [copy](const void*) {
      std::memset(static_cast<void*>(copy->data()), 0, copy->size() * sizeof(CompactCell));
    });
    return v;
  }

 private:
  MemoryOctree* tree_;
  std::vector<std::shared_ptr<std::vector<CompactCell>>> kept_;
};

// A visitor that walks other rays through the walk's own lending table (fog
// does: its transmittance rays start inside its primary walk) ends the
// loans the outer walk reads from; the outer walk lends its brick again and
// meets the same voxels as without the inner walks.
TEST(LendingBrickTable, AWalkInsideAVisitorLeavesTheOuterWalkItsBrick) {
  std::mt19937_64 rng(11);
  std::vector<LeafPoint> pts;
  for (int i = 0; i < 20000; ++i)
    pts.push_back({rng() % 64, rng() % 64, rng() % 64, kEmptyRef});
  auto built = MemoryOctree::Build(pts, 6, 3);  // bricks of 8^3
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  std::unique_ptr<MemoryOctree> tree = std::move(built).value();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int checked = 0, revisited = 0;
  for (int r = 0; r < 200; ++r) {
    const Ray outer{glm::dvec3(-5, 32 + 20 * u(rng), 32 + 20 * u(rng)),
                    glm::dvec3(1, 0.3 * u(rng), 0.3 * u(rng))};
    // The plain walk, through a table of its own.
    ScrubbingSource plain_source(tree.get());
    LendingBrickTable plain_table(&plain_source, 0);
    OctreeView plain_view = tree->view();
    plain_view.bricks = &plain_table;
    auto plain = AutoTracer<double>::Create(plain_view, 3);
    ASSERT_TRUE(plain.ok());
    std::vector<glm::i64vec3> want, got;
    ASSERT_TRUE(plain->Traverse(outer, [&](const Hit& h) { want.push_back(h.voxel); return true; }).ok());
    // The same walk whose visitor walks a ray across the grid at each hit,
    // through one table of one slot: every inner walk takes the slot.
    ScrubbingSource source(tree.get());
    LendingBrickTable table(&source, 0);
    OctreeView view = tree->view();
    view.bricks = &table;
    auto tracer = AutoTracer<double>::Create(view, 3);
    ASSERT_TRUE(tracer.ok());
    ASSERT_TRUE(tracer
                    ->Traverse(outer,
                               [&](const Hit& h) {
                                 got.push_back(h.voxel);
                                 const Ray inner{glm::dvec3(h.voxel) + 0.5, glm::dvec3(0.2, 1, -0.7)};
                                 int n = 0;
                                 EXPECT_TRUE(tracer->Traverse(inner, [&](const Hit&) { return ++n < 4; }).ok());
                                 revisited += n > 0;
                                 return true;
                               })
                    .ok());
    EXPECT_EQ(got, want) << "ray " << r;
    checked += int(want.size());
  }
  EXPECT_GT(checked, 500);
  EXPECT_GT(revisited, 500);
}

}  // namespace
}  // namespace vox

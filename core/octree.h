// The octree every vox traversal walks, split into a resident top and bricks
// that are fetched on demand; and the pre-order pools it is built from.
//
// Two forms of a pool. Both index a cell's children by the octal digit
// `x_bit | y_bit << 1 | z_bit << 2` of the level's bit of the voxel
// coordinates, and both have their root cell at index 0.
//
// Build form (`Cell`, 32 bytes: 8 NodeRefs), in pre-order, as BuildCells
// makes it and as the store's files hold the top (storage/FORMAT.md). A
// NodeRef means, by where it stands:
//   - 0 (kEmptyRef): the octant is empty, at any level;
//   - at the last level of the tree (children of level-1 cells): an occupied
//     voxel, whose payload index in its pool is `ref - 1`;
//   - elsewhere, with kBrickBit set: brick `ref & kBrickIdMask`, whose pool's
//     root cell is the child octant (fetch it through a BrickSource);
//   - elsewhere, without kBrickBit: index of the child cell in the same pool.
//
// Traversal form (`CompactCell`, 4 bytes), in level order (breadth first,
// children in digit order), which is what OctreeView and BrickView hand out.
// Level order keeps each cell's non-empty children contiguous, so a cell is
// its 8-bit child mask plus the index of its first non-empty child; child d
// is `first + popcount(mask & ((1 << d) - 1))` (ChildIndex), and an empty
// octant is a clear mask bit. What the index names depends on the level, as
// above: a cell of the same pool, a payload (last level: leaves are numbered
// in level order, which at the last level is Morton order), or, at the
// brick level of the top, a brick id (ids are Morton order of the bricks, so
// level order too). Indices fit 24 bits: a pool may hold at most 2^24 cells,
// children and payloads (bricks of depth <= 7 always do).
//
// So the top pool (resident) holds the levels above the brick level and
// refers to bricks; a brick's pool holds the subtree under one octant of the
// brick level, down to the voxels, and never refers to another brick.
//
// Thread safety: pools are immutable once built and shared freely.
// BrickSource implementations must be thread-safe.
#ifndef VOX_CORE_OCTREE_H_
#define VOX_CORE_OCTREE_H_

#include <bit>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/util/status.h"

// Forces inlining of a traversal's per-ray helpers into their one caller
// (the set-up, the jumps and the transition run once or twice per ray,
// and a call per helper cost a measurable share of a short ray).
#define VOX_ALWAYS_INLINE [[gnu::always_inline]] inline

namespace vox {

using NodeRef = uint32_t;
inline constexpr NodeRef kEmptyRef = 0;
inline constexpr NodeRef kBrickBit = 0x80000000u;
inline constexpr NodeRef kBrickIdMask = 0x7fffffffu;
inline constexpr uint32_t kNoBrick = 0xffffffffu;

// Deepest octree vox handles: 2^40 voxels per axis, OpenVDB's 32-bit index space.
inline constexpr int kMaxLevels = 40;
// Deepest single DDA step: its packed XYZ register has 3 x (20 + 1) bits.
inline constexpr int kMaxStepLevels = 20;

struct Cell {
  NodeRef child[8];
};
static_assert(sizeof(Cell) == 32, "Cell is 8 x uint32");

// A traversal-form cell: child mask in bits 0..7, index of the first
// non-empty child in bits 8..31 (0 when the mask is 0).
struct CompactCell {
  uint32_t bits = 0;
};
static_assert(sizeof(CompactCell) == 4, "CompactCell is one uint32");
// Largest index a CompactCell holds.
inline constexpr uint32_t kMaxCompactIndex = (uint32_t(1) << 24) - 1;

inline constexpr CompactCell MakeCompactCell(uint32_t first, uint32_t mask) {
  return CompactCell{first << 8 | (mask & 0xffu)};
}
inline constexpr uint32_t ChildMask(CompactCell c) { return c.bits & 0xffu; }
inline constexpr uint32_t FirstChild(CompactCell c) { return c.bits >> 8; }
inline constexpr bool HasChild(CompactCell c, unsigned digit) { return (c.bits >> digit) & 1u; }
// The number of set bits of an 8-bit mask: POPCNT where the target has it
// (x86-64-v2), else by table (on the baseline x86-64 target std::popcount
// is a call into libgcc).
inline uint32_t Popcount8(uint32_t mask8) {
#ifdef __POPCNT__
  return uint32_t(std::popcount(mask8 & 0xffu));
#else
  static constexpr auto kPop8 = [] {
    struct T { uint8_t v[256]; } t{};
    for (int i = 0; i < 256; ++i) t.v[i] = uint8_t((i & 1) + ((i >> 1) & 1) + ((i >> 2) & 1) +
                                                   ((i >> 3) & 1) + ((i >> 4) & 1) +
                                                   ((i >> 5) & 1) + ((i >> 6) & 1) + (i >> 7));
    return t;
  }();
  return kPop8.v[mask8 & 0xffu];
#endif
}
// The index of child `digit`. REQUIRES: HasChild(c, digit).
inline uint32_t ChildIndex(CompactCell c, unsigned digit) {
  return (c.bits >> 8) + Popcount8(c.bits & ((1u << digit) - 1u));
}

inline constexpr bool IsBrickRef(NodeRef r) { return (r & kBrickBit) != 0; }
inline constexpr NodeRef MakeBrickRef(uint32_t id) { return kBrickBit | id; }
inline constexpr NodeRef MakeLeafRef(uint32_t payload) { return payload + 1; }
inline constexpr uint32_t LeafPayload(NodeRef r) { return r - 1; }

// A fetched brick: its cell pool (traversal form), kept alive (pinned) as long as `pin` is held.
// `data` is the source's own record of the brick (storage: the decoded brick
// with its attribute planes), opaque to core, alive as long as the cells.
struct BrickView {
  const CompactCell* cells = nullptr;
  uint32_t num_cells = 0;
  std::shared_ptr<const void> pin;
  const void* data = nullptr;
};

// Where bricks come from: storage's paging cache, or an in-memory octree.
class BrickSource {
 public:
  virtual ~BrickSource() = default;
  // Returns brick `id`'s cells. Thread-safe. Errors (I/O, checksum) name the
  // brick and the file.
  virtual StatusOr<BrickView> FetchBrick(uint32_t id) = 0;
  // Brick `id`'s cells if they are in memory now, without waiting for a
  // read; otherwise UnavailableError (and nothing is read: the caller asks
  // for the read, e.g. Store::Prefetch, and tries again later). Sources that
  // hold every brick in memory answer as FetchBrick.
  virtual StatusOr<BrickView> FetchBrickIfReady(uint32_t id) { return FetchBrick(id); }

  // Lending: a source used by one thread that keeps the bricks it hands out
  // pinned itself (a per-thread table in front of a shared cache) returns
  // true from lends() and implements LendBrick: brick `id`'s view, valid
  // until the next FetchBrick or LendBrick call on this source, or nullptr
  // with *error set. A traversal then takes no pin (no reference count) per
  // brick it enters.
  virtual bool lends() const { return false; }
  virtual const BrickView* LendBrick(uint32_t id, Status* error) {
    *error = InternalError("this brick source does not lend (brick " + std::to_string(id) + ")");
    return nullptr;
  }
  // A lending source's count of the lends that may have ended earlier
  // loans (a brick replaced in its slot), for a walk whose visitor walks
  // other rays through the same source (fog's transmittance rays inside its
  // primary walk): when the count moved during a visit, the walk lends its
  // brick again before it reads on. Null: loans end only as LendBrick says.
  virtual const uint64_t* lend_epoch() const { return nullptr; }
};

// What a traversal needs to walk a tree: non-owning.
struct OctreeView {
  int levels = 0;               // N: the grid is [0, 2^N)^3 voxels
  int brick_level = 0;          // 1..N: the top's levels; N when there are no bricks
  const CompactCell* top = nullptr;  // resident pool (traversal form); cell 0 is the root
  uint32_t top_cells = 0;
  BrickSource* bricks = nullptr;  // may be null when the top refers to no brick
};

// Child `digit` of a traversal-form cell at tree level `level` (0: the root)
// of `tree`, for walkers outside the tracers (tests, tools): empty, a cell of
// the same pool, a brick (its pool's cell 0 is the child), or a payload.
struct ChildRef {
  enum Kind { kEmpty, kCell, kBrick, kPayload } kind = kEmpty;
  uint32_t index = 0;
};
inline ChildRef ChildOf(CompactCell c, unsigned digit, int level, const OctreeView& tree) {
  if (!HasChild(c, digit)) return {};
  const uint32_t i = ChildIndex(c, digit);
  if (level + 1 == tree.levels) return {ChildRef::kPayload, i};
  if (level + 1 == tree.brick_level) return {ChildRef::kBrick, i};
  return {ChildRef::kCell, i};
}

// A voxel with the leaf (or brick) reference to place at the last level of a
// pool being built. Coordinates are local to the pool's subtree.
struct LeafPoint {
  uint64_t x = 0, y = 0, z = 0;
  NodeRef ref = kEmptyRef;
};

// The Morton key of a point whose coordinates fit 21 bits: digit
// x | y << 1 | z << 2 per level, so keys order points as MortonLess does.
inline uint64_t MortonKey21(uint64_t x, uint64_t y, uint64_t z) {
  auto spread = [](uint64_t v) {  // bit i -> bit 3i
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  return spread(x) | spread(y) << 1 | spread(z) << 2;
}

// Orders points by Morton code (z most significant within a level's digit);
// `levels` need not be known: coordinates of up to 64 bits compare correctly.
bool MortonLess(const LeafPoint& a, const LeafPoint& b);

// Puts `points` in MortonLess order, stably (equal points keep their order).
// Points whose coordinates all fit 21 bits are ordered by MortonKey21; points
// already in order cost one pass over them and no allocation, so a producer
// that hands over sorted points (ingest) is never sorted twice.
void SortMorton(std::vector<LeafPoint>* points);

// Builds the cell pool of a `levels`-level octree over `points`, which must be
// sorted by MortonLess, unique, and have coordinates < 2^levels. Each point's
// `ref` is stored at the last level. An empty span gives one empty root cell.
// REQUIRES: 1 <= levels <= kMaxLevels.
std::vector<Cell> BuildCells(std::span<const LeafPoint> points, int levels);

// The traversal form of a `levels`-level build-form pool whose cell refs each
// name a cell of the pool (as ValidatePool-checked or BuildCells pools do).
// Its last-level refs (leaf refs, or brick refs when `bricks_at_last_level`)
// must number 0, 1, 2, ... in level order (payloads or brick ids in Morton
// order, as BuildCells and the store's writer make them): Corruption naming
// the first that does not, or an index beyond kMaxCompactIndex.
StatusOr<std::vector<CompactCell>> LevelOrderPool(std::span<const Cell> cells, int levels,
                                                  bool bricks_at_last_level);

// An octree held in memory, split at `brick_level` like a store: for tests,
// the demo and tools. Payload indices are the positions of the voxels in
// `voxels()` (sorted in Morton order, global coordinates).
class MemoryOctree : public BrickSource {
 public:
  // brick_level in [1, levels]: levels above it are the top; brick_level ==
  // levels keeps everything in the top (no bricks). Duplicates are merged.
  static StatusOr<std::unique_ptr<MemoryOctree>> Build(std::vector<LeafPoint> voxels, int levels,
                                                       int brick_level);

  OctreeView view() {
    return {levels_, brick_level_, top_.data(), uint32_t(top_.size()), this};
  }
  int levels() const { return levels_; }
  int brick_level() const { return brick_level_; }
  const std::vector<LeafPoint>& voxels() const { return voxels_; }
  size_t num_bricks() const { return bricks_.size(); }
  // Payload index -> position in voxels(), for a hit in brick `brick` (or kNoBrick).
  uint32_t VoxelIndex(uint32_t brick, uint32_t payload) const;

  StatusOr<BrickView> FetchBrick(uint32_t id) override;

 private:
  int levels_ = 0, brick_level_ = 0;
  std::vector<LeafPoint> voxels_;
  std::vector<CompactCell> top_;
  std::vector<std::shared_ptr<std::vector<CompactCell>>> bricks_;
  std::vector<uint32_t> brick_first_voxel_;
};

}  // namespace vox

#endif  // VOX_CORE_OCTREE_H_

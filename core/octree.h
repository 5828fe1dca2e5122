// The octree every vox traversal walks: cells of 8 child references, split
// into a resident top and bricks that are fetched on demand.
//
// Layout. A cell is an octant: 8 NodeRefs indexed by the octal digit
// `x_bit | y_bit << 1 | z_bit << 2` of the level's bit of the voxel
// coordinates. Cells live in pools (arrays of Cell); a pool's root cell is
// index 0. A NodeRef means, by where it stands:
//   - 0 (kEmptyRef): the octant is empty, at any level;
//   - at the last level of the tree (children of level-1 cells): an occupied
//     voxel, whose payload index in its pool is `ref - 1`;
//   - elsewhere, with kBrickBit set: brick `ref & kBrickIdMask`, whose pool's
//     root cell is the child octant (fetch it through a BrickSource);
//   - elsewhere, without kBrickBit: index of the child cell in the same pool.
// So the top pool (resident) holds the levels above the brick level and
// refers to bricks; a brick's pool holds the subtree under one octant of the
// brick level, down to the voxels, and never refers to another brick.
//
// Thread safety: Cell pools are immutable once built and shared freely.
// BrickSource implementations must be thread-safe.
#ifndef VOX_CORE_OCTREE_H_
#define VOX_CORE_OCTREE_H_

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/status.h"

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

inline constexpr bool IsBrickRef(NodeRef r) { return (r & kBrickBit) != 0; }
inline constexpr NodeRef MakeBrickRef(uint32_t id) { return kBrickBit | id; }
inline constexpr NodeRef MakeLeafRef(uint32_t payload) { return payload + 1; }
inline constexpr uint32_t LeafPayload(NodeRef r) { return r - 1; }

// A fetched brick: its cell pool, kept alive (pinned) as long as `pin` is held.
// `data` is the source's own record of the brick (storage: the decoded brick
// with its attribute planes), opaque to core, alive as long as the cells.
struct BrickView {
  const Cell* cells = nullptr;
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
};

// What a traversal needs to walk a tree: non-owning.
struct OctreeView {
  int levels = 0;               // N: the grid is [0, 2^N)^3 voxels
  const Cell* top = nullptr;    // resident pool; its cell 0 is the root
  uint32_t top_cells = 0;
  BrickSource* bricks = nullptr;  // may be null when the top refers to no brick
};

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

// An octree held in memory, split at `brick_level` like a store: for tests,
// the demo and tools. Payload indices are the positions of the voxels in
// `voxels()` (sorted in Morton order, global coordinates).
class MemoryOctree : public BrickSource {
 public:
  // brick_level in [1, levels]: levels above it are the top; brick_level ==
  // levels keeps everything in the top (no bricks). Duplicates are merged.
  static StatusOr<std::unique_ptr<MemoryOctree>> Build(std::vector<LeafPoint> voxels, int levels,
                                                       int brick_level);

  OctreeView view() { return {levels_, top_.data(), uint32_t(top_.size()), this}; }
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
  std::vector<Cell> top_;
  std::vector<std::shared_ptr<std::vector<Cell>>> bricks_;
  std::vector<uint32_t> brick_first_voxel_;
};

}  // namespace vox

#endif  // VOX_CORE_OCTREE_H_

#include "core/octree.h"

#include <algorithm>
#include <utility>
#include <string>

namespace vox {
namespace {

// True when the highest set bit of a is below that of b.
inline bool LessMsb(uint64_t a, uint64_t b) { return a < b && a < (a ^ b); }

// Appends the subtree over points[begin, end) whose octant digit is taken at
// `bit`; returns its cell index.
NodeRef BuildRec(std::span<const LeafPoint> pts, size_t begin, size_t end, int bit,
                 std::vector<Cell>* cells) {
  NodeRef index = NodeRef(cells->size());
  cells->push_back(Cell{});
  auto digit = [bit](const LeafPoint& p) {
    return unsigned((p.x >> bit) & 1) | unsigned(((p.y >> bit) & 1) << 1) |
           unsigned(((p.z >> bit) & 1) << 2);
  };
  size_t i = begin;
  while (i < end) {
    unsigned dg = digit(pts[i]);
    size_t j = i + 1;
    while (j < end && digit(pts[j]) == dg) ++j;
    NodeRef ref = bit == 0 ? pts[i].ref : BuildRec(pts, i, j, bit - 1, cells);
    (*cells)[index].child[dg] = ref;
    i = j;
  }
  return index;
}

}  // namespace

bool MortonLess(const LeafPoint& a, const LeafPoint& b) {
  uint64_t dx = a.x ^ b.x, dy = a.y ^ b.y, dz = a.z ^ b.z;
  // The axis whose highest differing bit is highest decides; at equal bit
  // positions z outranks y outranks x (the digit is x | y << 1 | z << 2).
  int axis = 2;
  uint64_t best = dz;
  if (LessMsb(best, dy)) {
    axis = 1;
    best = dy;
  }
  if (LessMsb(best, dx)) axis = 0;
  switch (axis) {
    case 0: return a.x < b.x;
    case 1: return a.y < b.y;
    default: return a.z < b.z;
  }
}

void SortMorton(std::vector<LeafPoint>* points) {
  std::vector<LeafPoint>& p = *points;
  if (p.size() < 2) return;
  // One pass: do all coordinates fit 21 bits, and are the keys in order?
  uint64_t bits = p[0].x | p[0].y | p[0].z;
  uint64_t prev = MortonKey21(p[0].x, p[0].y, p[0].z);
  bool sorted = true;
  for (size_t i = 1; i < p.size(); ++i) {
    bits |= p[i].x | p[i].y | p[i].z;
    const uint64_t key = MortonKey21(p[i].x, p[i].y, p[i].z);
    sorted = sorted && !(key < prev);
    prev = key;
  }
  if (bits >> 21 == 0) {
    if (sorted) return;
    std::vector<std::pair<uint64_t, size_t>> keyed(p.size());
    for (size_t i = 0; i < p.size(); ++i) keyed[i] = {MortonKey21(p[i].x, p[i].y, p[i].z), i};
    std::sort(keyed.begin(), keyed.end());  // ties by position: stable
    std::vector<LeafPoint> out(p.size());
    for (size_t k = 0; k < keyed.size(); ++k) out[k] = p[keyed[k].second];
    p.swap(out);
    return;
  }
  if (!std::is_sorted(p.begin(), p.end(), MortonLess))
    std::stable_sort(p.begin(), p.end(), MortonLess);
}

std::vector<Cell> BuildCells(std::span<const LeafPoint> points, int levels) {
  std::vector<Cell> cells;
  if (points.empty()) {
    cells.push_back(Cell{});
    return cells;
  }
  cells.reserve(points.size() / 2 + levels + 1);
  BuildRec(points, 0, points.size(), levels - 1, &cells);
  return cells;
}

StatusOr<std::vector<CompactCell>> LevelOrderPool(std::span<const Cell> cells, int levels,
                                                  bool bricks_at_last_level) {
  if (cells.empty()) return CorruptionError("octree pool has no root cell");
  if (cells.size() > size_t(kMaxCompactIndex) + 1)
    return CorruptionError("octree pool has " + std::to_string(cells.size()) +
                           " cells; a traversal pool holds at most 2^24");
  std::vector<CompactCell> out;
  out.reserve(cells.size());
  // Breadth first: `level` holds the build-form indices of one level's cells
  // in level order; their children, in digit order, make the next level.
  std::vector<uint32_t> level{0}, next;
  for (int l = 0; l < levels && !level.empty(); ++l) {
    const bool last = l == levels - 1;
    next.clear();
    const size_t done = out.size();  // cells of the levels above
    uint64_t count = 0;  // children of this level so far
    for (uint32_t index : level) {
      const Cell& c = cells[index];
      uint32_t mask = 0;
      const uint64_t first = count;
      for (unsigned d = 0; d < 8; ++d) {
        const NodeRef r = c.child[d];
        if (r == kEmptyRef) continue;
        mask |= 1u << d;
        if (!last) {
          if (IsBrickRef(r) || r >= cells.size() ||
              done + level.size() + next.size() >= cells.size())
            return CorruptionError("octree cell " + std::to_string(index) + " refers to cell " +
                                   std::to_string(r) + " (of " + std::to_string(cells.size()) +
                                   ") that is not a new cell");
          next.push_back(r);
        } else {
          const bool brick = IsBrickRef(r);
          const uint64_t v = brick ? (r & kBrickIdMask) : uint64_t(LeafPayload(r));
          if (brick != bricks_at_last_level || v != count)
            return CorruptionError(
                "octree cell " + std::to_string(index) + " child " + std::to_string(d) + " is " +
                (brick ? "brick " : "payload ") + std::to_string(v) + " where " +
                (bricks_at_last_level ? "brick " : "payload ") + std::to_string(count) +
                " belongs (last-level refs must number 0, 1, ... in Morton order)");
        }
        ++count;
      }
      if (first > kMaxCompactIndex)
        return CorruptionError("octree level " + std::to_string(l + 1) + " has more than 2^24 " +
                               (last ? (bricks_at_last_level ? "bricks" : "voxels") : "cells") +
                               "; a traversal pool indexes at most 2^24");
      out.push_back(MakeCompactCell(mask == 0 ? 0 : uint32_t(first), mask));
    }
    if (!last) {  // firsts so far count from the next level's start
      const uint64_t start = out.size();
      for (size_t i = out.size() - level.size(); i < out.size(); ++i) {
        if (ChildMask(out[i]) == 0) continue;
        const uint64_t f = start + FirstChild(out[i]);
        if (f > kMaxCompactIndex) return CorruptionError("octree pool has more than 2^24 cells");
        out[i] = MakeCompactCell(uint32_t(f), ChildMask(out[i]));
      }
    }
    level.swap(next);
  }
  if (out.size() != cells.size())
    return CorruptionError("octree pool has " + std::to_string(cells.size()) + " cells but " +
                           std::to_string(out.size()) + " are reachable in " +
                           std::to_string(levels) + " levels");
  return out;
}

StatusOr<std::unique_ptr<MemoryOctree>> MemoryOctree::Build(std::vector<LeafPoint> voxels,
                                                            int levels, int brick_level) {
  if (levels < 1 || levels > kMaxLevels)
    return InvalidArgumentError("octree levels " + std::to_string(levels) + " outside 1..40");
  if (brick_level < 1 || brick_level > levels)
    return InvalidArgumentError("brick level " + std::to_string(brick_level) + " outside 1.." +
                                std::to_string(levels));
  const uint64_t size = uint64_t(1) << levels;
  for (const LeafPoint& v : voxels)
    if (v.x >= size || v.y >= size || v.z >= size)
      return InvalidArgumentError("voxel (" + std::to_string(v.x) + "," + std::to_string(v.y) +
                                  "," + std::to_string(v.z) + ") outside a 2^" +
                                  std::to_string(levels) + " grid");
  SortMorton(&voxels);
  voxels.erase(std::unique(voxels.begin(), voxels.end(),
                           [](const LeafPoint& a, const LeafPoint& b) {
                             return a.x == b.x && a.y == b.y && a.z == b.z;
                           }),
               voxels.end());
  auto tree = std::unique_ptr<MemoryOctree>(new MemoryOctree());
  tree->levels_ = levels;
  tree->brick_level_ = brick_level;
  if (brick_level == levels) {
    for (size_t i = 0; i < voxels.size(); ++i) voxels[i].ref = MakeLeafRef(uint32_t(i));
    VOX_ASSIGN_OR_RETURN(tree->top_, LevelOrderPool(BuildCells(voxels, levels), levels, false));
    tree->voxels_ = std::move(voxels);
    return tree;
  }
  // One brick per occupied octant of the brick level: runs of equal
  // (coord >> sub) are contiguous in Morton order.
  const int sub = levels - brick_level;
  std::vector<LeafPoint> top_points;
  size_t i = 0;
  while (i < voxels.size()) {
    const LeafPoint& head = voxels[i];
    size_t j = i + 1;
    while (j < voxels.size() && (voxels[j].x >> sub) == (head.x >> sub) &&
           (voxels[j].y >> sub) == (head.y >> sub) && (voxels[j].z >> sub) == (head.z >> sub))
      ++j;
    const uint64_t lmask = (uint64_t(1) << sub) - 1;
    std::vector<LeafPoint> local(voxels.begin() + i, voxels.begin() + j);
    for (size_t k = 0; k < local.size(); ++k) {
      local[k].x &= lmask;
      local[k].y &= lmask;
      local[k].z &= lmask;
      local[k].ref = MakeLeafRef(uint32_t(k));
    }
    uint32_t id = uint32_t(tree->bricks_.size());
    VOX_ASSIGN_OR_RETURN(std::vector<CompactCell> pool,
                         LevelOrderPool(BuildCells(local, sub), sub, false));
    tree->bricks_.push_back(std::make_shared<std::vector<CompactCell>>(std::move(pool)));
    tree->brick_first_voxel_.push_back(uint32_t(i));
    top_points.push_back({head.x >> sub, head.y >> sub, head.z >> sub, MakeBrickRef(id)});
    i = j;
  }
  VOX_ASSIGN_OR_RETURN(tree->top_, LevelOrderPool(BuildCells(top_points, brick_level),
                                                  brick_level, true));
  tree->voxels_ = std::move(voxels);
  return tree;
}

uint32_t MemoryOctree::VoxelIndex(uint32_t brick, uint32_t payload) const {
  return brick == kNoBrick ? payload : brick_first_voxel_[brick] + payload;
}

StatusOr<BrickView> MemoryOctree::FetchBrick(uint32_t id) {
  if (id >= bricks_.size())
    return CorruptionError("brick " + std::to_string(id) + " does not exist (" +
                           std::to_string(bricks_.size()) + " bricks)");
  const auto& b = bricks_[id];
  return BrickView{b->data(), uint32_t(b->size()), b};
}

}  // namespace vox

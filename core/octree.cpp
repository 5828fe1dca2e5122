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
    tree->top_ = BuildCells(voxels, levels);
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
    tree->bricks_.push_back(std::make_shared<std::vector<Cell>>(BuildCells(local, sub)));
    tree->brick_first_voxel_.push_back(uint32_t(i));
    top_points.push_back({head.x >> sub, head.y >> sub, head.z >> sub, MakeBrickRef(id)});
    i = j;
  }
  tree->top_ = BuildCells(top_points, brick_level);
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

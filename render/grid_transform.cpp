#include "render/grid_transform.h"

#include <algorithm>
#include <cmath>
#include <glm/matrix.hpp>
#include <limits>

namespace vox {

StatusOr<GridTransform> GridTransform::FromMeta(const StoreMeta& meta) {
  const glm::dmat4& m = meta.index_to_world;
  glm::dmat3 lin(m);
  double det = glm::determinant(lin);
  if (!std::isfinite(det) || std::fabs(det) < 1e-300)
    return InvalidArgumentError("volume '" + meta.grid_name + "': index_to_world is singular");
  GridTransform t;
  t.grid_to_world_linear = lin;
  t.world_to_grid_linear = glm::inverse(lin);
  t.normal_to_world = glm::transpose(t.world_to_grid_linear);
  glm::dvec3 trans(m[3]);
  glm::dvec3 shift = glm::dvec3(meta.origin) - glm::dvec3(0.5);  // index = grid + origin - 0.5
  // world = lin * (g + shift) + trans
  t.grid_to_world_offset = lin * shift + trans;
  t.world_to_grid_offset = -t.world_to_grid_linear * trans - shift;
  return t;
}

void WorldBounds(const StoreMeta& meta, glm::dvec3* lo, glm::dvec3* hi) {
  glm::dvec3 a = glm::dvec3(meta.bbox_min) - 0.5, b = glm::dvec3(meta.bbox_max) + 0.5;
  if (meta.bbox_max.x < meta.bbox_min.x) {
    a = glm::dvec3(meta.origin) - 0.5;
    b = a + std::ldexp(1.0, meta.levels);
  }
  *lo = glm::dvec3(std::numeric_limits<double>::infinity());
  *hi = -*lo;
  for (int c = 0; c < 8; ++c) {
    glm::dvec4 p((c & 1) ? b.x : a.x, (c & 2) ? b.y : a.y, (c & 4) ? b.z : a.z, 1.0);
    glm::dvec3 w(meta.index_to_world * p);
    *lo = glm::min(*lo, w);
    *hi = glm::max(*hi, w);
  }
}

StatusOr<std::unique_ptr<MemoryVolume>> MemoryVolume::Create(StoreMeta meta,
                                                             std::vector<MemoryVoxel> voxels) {
  std::vector<LeafPoint> points(voxels.size());
  std::vector<uint32_t> order(voxels.size());
  for (size_t i = 0; i < voxels.size(); ++i) {
    points[i] = {voxels[i].x, voxels[i].y, voxels[i].z, kEmptyRef};
    order[i] = uint32_t(i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return MortonLess(points[a], points[b]); });
  std::vector<LeafPoint> sorted;
  auto vol = std::unique_ptr<MemoryVolume>(new MemoryVolume());
  sorted.reserve(points.size());
  for (uint32_t i : order) {
    if (!sorted.empty() && sorted.back().x == points[i].x && sorted.back().y == points[i].y &&
        sorted.back().z == points[i].z)
      continue;
    sorted.push_back(points[i]);
    vol->attrs_.push_back(voxels[i].attr);
  }
  const size_t count = sorted.size();
  glm::i64vec3 lo(std::numeric_limits<int64_t>::max()), hi(std::numeric_limits<int64_t>::min());
  for (const LeafPoint& p : sorted) {
    glm::i64vec3 g(int64_t(p.x), int64_t(p.y), int64_t(p.z));
    lo = glm::min(lo, g);
    hi = glm::max(hi, g);
  }
  VOX_ASSIGN_OR_RETURN(vol->tree_,
                       MemoryOctree::Build(std::move(sorted), meta.levels, meta.brick_level));
  if (vol->tree_->voxels().size() != count)
    return InternalError("memory octree changed the voxel count");
  meta.voxel_count = count;
  meta.brick_count = vol->tree_->num_bricks();
  if (count > 0) {
    meta.bbox_min = lo + meta.origin;
    meta.bbox_max = hi + meta.origin;
  } else {
    meta.bbox_min = glm::i64vec3(0);
    meta.bbox_max = glm::i64vec3(-1);
  }
  vol->meta_ = std::move(meta);
  return vol;
}

StatusOr<VoxelAttributes> MemoryVolume::Attributes(uint32_t brick, uint32_t payload) {
  if (brick != kNoBrick && brick >= tree_->num_bricks())
    return CorruptionError("memory volume: no brick " + std::to_string(brick));
  uint32_t i = tree_->VoxelIndex(brick, payload);
  if (i >= attrs_.size()) return CorruptionError("memory volume: payload out of range");
  return attrs_[i];
}

}  // namespace vox

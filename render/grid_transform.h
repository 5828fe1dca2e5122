// The renderer's view of a Volume (storage/volume.h): GridTransform, the
// affine maps between world space and the tracer's grid space, and
// WorldBounds, for the default camera. MemoryVolume, the in-memory Volume of
// the tests and demos.
//
// Thread safety: GridTransform is an immutable value; a MemoryVolume is
// thread-safe (Attributes and the MemoryOctree behind view() are read-only).
#ifndef VOX_RENDER_GRID_TRANSFORM_H_
#define VOX_RENDER_GRID_TRANSFORM_H_

#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <memory>
#include <string>
#include <vector>

#include "core/octree.h"
#include "core/util/status.h"
#include "storage/volume.h"

namespace vox {

// The affine maps between world space and the tracer's grid space: grid
// point g = inverse(M) * W + 0.5 - origin, where M is meta.index_to_world.
struct GridTransform {
  glm::dmat3 world_to_grid_linear{1.0};  // inverse of M's linear part
  glm::dvec3 world_to_grid_offset{0.0};
  glm::dmat3 grid_to_world_linear{1.0};
  glm::dvec3 grid_to_world_offset{0.0};
  glm::dmat3 normal_to_world{1.0};  // inverse transpose of M's linear part

  static StatusOr<GridTransform> FromMeta(const StoreMeta& meta);
  glm::dvec3 WorldToGrid(const glm::dvec3& w) const {
    return world_to_grid_linear * w + world_to_grid_offset;
  }
  glm::dvec3 GridToWorld(const glm::dvec3& g) const {
    return grid_to_world_linear * g + grid_to_world_offset;
  }
};

// World-space box of the occupied voxels (meta bbox), for the default camera.
void WorldBounds(const StoreMeta& meta, glm::dvec3* lo, glm::dvec3* hi);

// One voxel of a MemoryVolume: grid coordinates and attributes.
struct MemoryVoxel {
  uint64_t x = 0, y = 0, z = 0;
  VoxelAttributes attr;
};

class MemoryVolume : public Volume {
 public:
  // `meta` gives levels, brick_level, grid class, origin and placement; its
  // counts and bbox are filled in. Duplicate voxels keep the first.
  static StatusOr<std::unique_ptr<MemoryVolume>> Create(StoreMeta meta,
                                                        std::vector<MemoryVoxel> voxels);
  const StoreMeta& meta() const override { return meta_; }
  OctreeView view() override { return tree_->view(); }
  StatusOr<VoxelAttributes> Attributes(uint32_t brick, uint32_t payload) override;
  std::string description() const override { return "memory"; }

 private:
  StoreMeta meta_;
  std::unique_ptr<MemoryOctree> tree_;
  std::vector<VoxelAttributes> attrs_;  // in tree_->voxels() order
};

}  // namespace vox

#endif  // VOX_RENDER_GRID_TRANSFORM_H_

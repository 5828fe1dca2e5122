// vox::RenderVolume: what the renderer needs of a volume (the octree to
// trace, each voxel's attributes, the placement in world space), so it can
// render a Store or an in-memory octree alike. MemoryVolume is the in-memory
// one (tests, demos); StoreVolume (store_volume.h) adapts a Store.
//
// Thread safety: implementations are thread-safe (Attributes and the
// BrickSource behind view() are called from many render threads).
#ifndef VOX_RENDER_VOLUME_H_
#define VOX_RENDER_VOLUME_H_

#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <memory>
#include <string>
#include <vector>

#include "core/octree.h"
#include "core/status.h"
#include "storage/store.h"

namespace vox {

class RenderVolume {
 public:
  virtual ~RenderVolume() = default;
  virtual const StoreMeta& meta() const = 0;
  // The octree to trace; valid as long as the volume.
  virtual OctreeView view() = 0;
  // Attributes of the voxel hit in brick `brick` (kNoBrick: the top) at `payload`.
  virtual StatusOr<VoxelAttributes> Attributes(uint32_t brick, uint32_t payload) = 0;
  // The same for a hit of a traversal of view(), called from the traversal's
  // visitor (the hit's brick is pinned): volumes may read it from the brick.
  virtual StatusOr<VoxelAttributes> HitAttributes(const Hit& hit) {
    return Attributes(hit.brick, hit.payload);
  }
  // Brick cache counters (zero for volumes without a cache).
  virtual CacheStats cache_stats() const { return {}; }
  // Where the volume comes from, for EXR headers ("memory", a store path).
  virtual std::string description() const = 0;
};

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

class MemoryVolume : public RenderVolume {
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

#endif  // VOX_RENDER_VOLUME_H_

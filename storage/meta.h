// What a store is and what its voxels carry: StoreMeta (a store's grid,
// placement, counts and attribute set, as the index file records it; format
// in storage/FORMAT.md), VoxelAttributes and GridClass. Plain values.
//
// Coordinates: grid coordinates g in [0, 2^levels)^3 are what the octree and
// the tracer see. OpenVDB index coordinates are ijk = g + origin. World
// placement is OpenVDB's: voxel ijk covers index_to_world([ijk - 0.5,
// ijk + 0.5)^3). The probe's index space is VDB's shifted by one half (voxel
// ijk is [ijk, ijk + 1)^3), so a probe point P is the grid point P - origin.
#ifndef VOX_STORAGE_META_H_
#define VOX_STORAGE_META_H_

#include <cstdint>
#include <string>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

namespace vox {

enum class GridClass : uint8_t { kLevelSet = 1, kFogVolume = 2 };

struct StoreMeta {
  std::string source_file;   // as given to vox-ingest
  std::string grid_name;
  GridClass grid_class = GridClass::kLevelSet;
  int levels = 0;            // N: the octree covers [0, 2^N)^3 grid voxels
  int brick_level = 0;       // levels above it are resident; a brick holds levels - brick_level
  glm::i64vec3 origin{0};    // VDB index coordinate of grid voxel (0,0,0)
  glm::i64vec3 bbox_min{0};  // VDB index bounds of the occupied voxels, inclusive
  glm::i64vec3 bbox_max{-1};
  glm::dmat4 index_to_world{1.0};  // OpenVDB's linear affine map (GLM column-major: world = M * (ijk, 1))
  double voxel_size = 1.0;         // uniform voxel size (max axis of the map's scale)
  uint64_t voxel_count = 0;        // occupied voxels
  uint64_t brick_count = 0;
  uint64_t top_cells = 0;
  bool has_normal = false;   // level sets: a quantised normal per voxel
  bool has_density = false;  // fog volumes: the density per voxel
  bool has_color = false;    // an RGB colour per voxel (from a vec3 grid)
  bool has_coverage = false; // level-of-detail stores: the fraction of a cell's voxels occupied
  bool has_temperature = false;  // format 1.3: a temperature per voxel (from a second float grid)
  double isovalue = 0.0;     // level sets: occupied when active and value <= isovalue
  double threshold = 0.0;    // fog volumes: occupied when active and density > threshold
  std::string build_options; // the ingest command's options, for the record
  // Level of detail (format 1.1, storage/lod.h): a coarse store of a
  // pyramid is the base store downsampled by 2^lod_level; it names the base
  // store's store_id and levels. 0 / 0 / 0 in a base store.
  int lod_level = 0;
  uint64_t lod_base_store_id = 0;
  int lod_base_levels = 0;
};

// What a brick keeps per occupied voxel. Fields the store does not have are
// zero (normal), 1 (density), 1,1,1 (colour), 1 (coverage) or 0 (temperature).
struct VoxelAttributes {
  glm::vec3 normal{0.0f};    // unit, in index space (the gradient of the distance field)
  float density = 1.0f;
  glm::vec3 color{1.0f};
  float coverage = 1.0f;     // level-of-detail cells: fraction of their voxels occupied
  float temperature = 0.0f;  // a second grid's value (Kelvin for blackbody fog)
};

}  // namespace vox

#endif  // VOX_STORAGE_META_H_

// Generated volumes for tests, the probe and the demo, so nothing needs data
// files: "sphere:R" (a 2-voxel shell), "torus:R", "cubes:R" (scattered solid
// boxes), "noise:R" (random sparse voxels), "corner:L" (one voxel at the far
// corner of a 2^L grid). R is the grid size per axis, rounded up to a power
// of two. Thread-safe; deterministic for a given spec.
#ifndef VOX_CORE_SHAPES_H_
#define VOX_CORE_SHAPES_H_

#include <string_view>
#include <vector>

#include "core/octree.h"
#include "core/util/status.h"

namespace vox {

struct ShapeVolume {
  int levels = 0;
  std::vector<LeafPoint> voxels;
};

StatusOr<ShapeVolume> GenerateShape(std::string_view spec);

}  // namespace vox

#endif  // VOX_CORE_SHAPES_H_

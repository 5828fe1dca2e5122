// Colour sampling: the RGB colour of a main-grid voxel, read from a vec3
// grid of the same file (Vec3f or Vec3d). Where the colour grid shares the
// main grid's transform the colour is its value at the voxel; otherwise it is
// sampled trilinearly at the voxel's world position, as
// openvdb::tools::BoxSampler does. Scalar grids are sampled the same way
// (NewScalarSource). Private to ingest and its tests.
//
// Thread safety: a ColorSource is shared; each thread takes its own
// ColorReader (NewReader), which reads leaf values through private copies.
#ifndef VOX_INGEST_INTERNAL_COLOR_H_
#define VOX_INGEST_INTERNAL_COLOR_H_

#include <memory>

#include <glm/glm.hpp>
#include <openvdb/openvdb.h>

namespace vox::ingest_internal {

class ColorReader {
 public:
  virtual ~ColorReader() = default;
  // The colour at main-grid index coordinate `ijk`.
  virtual glm::vec3 At(const openvdb::Coord& ijk) = 0;
};

class ColorSource {
 public:
  virtual ~ColorSource() = default;
  virtual std::unique_ptr<ColorReader> NewReader() = 0;
};

// A source over `grid` (a Vec3fGrid or Vec3dGrid; null for any other type)
// for a main grid with transform `main`, which must outlive the source.
std::unique_ptr<ColorSource> NewColorSource(openvdb::GridBase::Ptr grid,
                                            const openvdb::math::Transform& main);

// The same over a scalar `grid` (a FloatGrid or DoubleGrid; null for any
// other type): its value, or its trilinear sample, in all three components.
// vox-ingest --temperature reads a second grid of the file this way.
std::unique_ptr<ColorSource> NewScalarSource(openvdb::GridBase::Ptr grid,
                                             const openvdb::math::Transform& main);

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_COLOR_H_

// Beam start distances (Laine and Karras, "Efficient Sparse Voxel Octrees",
// section on beam optimisation): one coarse query per block of pixels finds
// a plane before which none of the block's primary rays can meet an
// occupied cell of the resident top, and each ray of the block starts its
// walk there (core/tracer.h, StartPlane: the first-step DDA jumps exactly to
// that point, so hits stay bit-identical). A block whose beam meets no
// occupied cell is a miss for all its rays, without a walk.
//
// The beam: the rays o(u, v) + s w(u, v) of a block, with o and w affine in
// the pixel coordinates (u, v) and one of them constant (a pinhole camera: o
// constant; an orthographic one: w constant). Every such ray lies inside the
// frustum bounded by the four planes through neighbouring corner rays, and
// ahead of the nearest corner origin. BeamStartPlane descends the top's
// cells front to back, each widened by kStartPlaneMargin voxels, keeps those
// that overlap the frustum, and returns the least s = dot(g, P) of the
// occupied cells of the first step's level it reaches (g: the mean corner
// direction). Reads only the resident top; no brick.
//
// Thread safety: stateless functions over an immutable tree.
#ifndef VOX_RENDER_BEAM_H_
#define VOX_RENDER_BEAM_H_

#include <glm/vec3.hpp>

#include "core/octree.h"
#include "core/tracer.h"

namespace vox {

// A block's four corner rays in grid space, in order around the block
// (e.g. (x0, y0), (x1, y0), (x1, y1), (x0, y1)), directions not normalised
// as a pair: any positive multiple of each works.
struct BeamCorners {
  glm::dvec3 o[4];
  glm::dvec3 d[4];
};

// The StartPlane every ray of the block satisfies, for a tracer with `n1`
// first-step levels over `tree`: cells of level min(n1, tree.brick_level)
// are the occupied units. Returns a plane with s_min = -inf (no hint) when
// the corners do not make a usable beam (directions more than 90 degrees
// apart, non-finite values, origins far from the grid: IsFarOrigin); s_min = +inf when the beam
// meets no occupied cell. `cells_tested` (optional) counts the box tests, for benchmarks.
StartPlane BeamStartPlane(const OctreeView& tree, int n1, const BeamCorners& beam,
                          uint64_t* cells_tested = nullptr);

}  // namespace vox

#endif  // VOX_RENDER_BEAM_H_

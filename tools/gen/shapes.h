// vox::gen shapes: procedural level-set shells described by a signed distance
// in index space, and scalar fields (fog densities), for vox-gen
// (tools/gen/generate.h).
//
// Placement, shared by every shape of grid size N (voxels per axis): grid
// voxel g (0 <= g < N) is OpenVDB index coordinate ijk = g - N/2; a voxel's
// centre is the point ijk itself (OpenVDB's convention), and world = ijk *
// voxel_size with voxel_size = 32 / (15 N): the unit sphere is 15/16 of the
// grid across, so the shapes span about [-1, 1]^3 in world space, centred on
// index (0,0,0), like `vdb_tool -sphere radius=1 voxel=2/(15N/16)`.
//
// Occupancy: a voxel is occupied when its centre's signed distance d (in
// voxels, negative inside) satisfies -band < d <= 0: the inner half of a
// narrow band of half-width `band`, which is what vox-ingest keeps of a
// `vdb_tool -sphere width=band` level set (active and value <= 0). A field
// (IsField) is a fog volume instead: a voxel is occupied where its centre's
// Density exceeds 0, and keeps that density (band plays no part).
//
// Thread safety: a Shape is immutable; all methods are thread-safe.
#ifndef VOX_GEN_SHAPES_H_
#define VOX_GEN_SHAPES_H_

#include <memory>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "core/util/status.h"
#include "storage/meta.h"

namespace vox::gen {

class Shape {
 public:
  virtual ~Shape() = default;
  // Level sets: the signed distance (or a first-order estimate of it) at
  // index point p, in voxels, negative inside. Fields: -Density(p).
  virtual double Distance(const glm::dvec3& p) const = 0;
  // Level sets: the outward unit normal (the distance field's gradient
  // direction) at p; zero where it is undefined. Fields: zero.
  virtual glm::dvec3 Normal(const glm::dvec3& p) const = 0;
  // False only when no point of the box [lo, hi] is occupied (level sets:
  // -band < Distance <= 0; fields: Density > 0). Conservative: true is
  // allowed for a box that holds none.
  virtual bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double band) const = 0;
  // Whether voxels carry a colour, and the colour at voxel centre p.
  virtual bool HasColor() const { return false; }
  virtual glm::dvec3 Color(const glm::dvec3& /*p*/) const { return glm::dvec3(1.0); }
  // A scalar field (a fog volume) rather than a level-set shell.
  virtual bool IsField() const { return false; }
  // Fields: the density at index point p; the voxel is occupied where > 0.
  virtual double Density(const glm::dvec3& /*p*/) const { return 1.0; }

  // Whether the voxel centred at p is occupied and, if so and `attr` is not
  // null, its attributes (normal and colour, or density): the rule above.
  bool Voxel(const glm::dvec3& p, double band, VoxelAttributes* attr) const;
};

// The shapes vox-gen knows, in the order `--help` lists them.
const std::vector<std::string>& ShapeNames();

// The world size of one voxel for grid size `size` (see Placement above).
double VoxelSize(uint64_t size);

// "sphere": the sphere of world radius 1 (15 size / 32 voxels), exact distance.
// "bumpy": that sphere displaced by deterministic multi-octave noise (21
//   plane waves, wavelengths 0.4 down to 0.4 / 64 world units, fixed seed):
//   f = |p| - r - D(p), distance estimate f / |grad f|, analytic normals.
// "rough": the sphere's voxels with each normal tilted by a fixed per-voxel
//   jitter (about 20 degrees, at most 37) and a speckled colour: attributes
//   that hardly compress (about 10 bytes per voxel on disk against the
//   sphere's 1), for stores larger than RAM written in a fraction of the
//   sphere's time.
// "fog": a ball of fog filling the unit sphere, density 1 - (|p| / r)^2 at
//   index point p (r = 15 size / 32 voxels, as the sphere's): 1 at the
//   centre, falling to 0 at the sphere; a dense volume (52% of the grid).
// "noise": a cloud field over the whole grid: density n(p) - 0.6 where
//   n(p) = 0.5 + sum_i a_i sin(k_i . p + phi_i) exceeds 0.6 (about a fifth of
//   the grid), 18 plane waves in 6 octaves of wavelength 0.5 world units
//   down to 0.5 / 32 and amplitudes halving with each octave, sum a_i = 0.5,
//   directions and phases from splitmix64 seeded with "vox-fog1".
// "pair": two spheres of 250 voxels radius (exact distance) centred at
//   index (-N/4, 0, 0) and (N/4, 0, 0), half the grid apart: the same
//   content in every grid from 2048^3 up, the rest empty (a sparse series).
StatusOr<std::unique_ptr<Shape>> MakeShape(const std::string& name, uint64_t size);

}  // namespace vox::gen

#endif  // VOX_GEN_SHAPES_H_

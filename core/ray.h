// Rays, hits and traversal counters shared by every tracer in vox.
// Plain value types; thread-compatible.
#ifndef VOX_CORE_RAY_H_
#define VOX_CORE_RAY_H_

#include <cstdint>
#include <string>

#include <glm/vec3.hpp>

#include "core/octree.h"

namespace vox {

// A ray in grid index space: voxel (i,j,k) is [i,i+1) x [j,j+1) x [k,k+1),
// the grid is [0, 2^N)^3. Points on the ray are origin + t * dir, t >= 0.
struct Ray {
  glm::dvec3 origin{0.0};
  glm::dvec3 dir{0.0, 0.0, 1.0};
};

// Refuses NaN or infinite components and a zero direction.
Status ValidateRay(const Ray& ray);

struct Hit {
  glm::i64vec3 voxel{0};      // grid coordinates of the occupied voxel
  double t = 0.0;             // ray parameter where the ray enters it (0 if it starts inside)
  uint32_t brick = kNoBrick;  // the brick holding its payload, kNoBrick for the top pool
  uint32_t payload = 0;       // payload index in that pool
  // The brick's BrickView::data (nullptr for the top pool): valid while the
  // visitor that receives the hit runs (the traversal pins the brick).
  const void* brick_data = nullptr;
};

struct TraceCounters {
  uint64_t rays = 0;
  uint64_t moves[3] = {0, 0, 0};  // DDA moves along x, y, z
  uint64_t driving_moves = 0;     // moves along the ray's driving axis
  uint64_t passive_moves = 0;     // moves along the two other axes
  uint64_t skips = 0;             // empty octants (or missed first-step voxels) left by the skip loop
  uint64_t cells_visited = 0;     // child references read while descending
  uint64_t transitions = 0;       // second steps started
  uint64_t brick_fetches = 0;     // bricks asked of the BrickSource
  uint64_t hits = 0;

  uint64_t total_moves() const { return moves[0] + moves[1] + moves[2]; }
  void Add(const TraceCounters& o);
  std::string ToString() const;
};

// Ray parameter where the ray enters the closed voxel `v` (clamped to >= 0),
// computed in double from the unscaled ray.
double VoxelEntryT(const Ray& ray, const glm::i64vec3& v);
// Ray parameter where the ray leaves voxel `v`.
double VoxelExitT(const Ray& ray, const glm::i64vec3& v);

}  // namespace vox

#endif  // VOX_CORE_RAY_H_

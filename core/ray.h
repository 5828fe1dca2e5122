// Rays, hits and traversal counters shared by every tracer in vox.
// Plain value types; thread-compatible.
#ifndef VOX_CORE_RAY_H_
#define VOX_CORE_RAY_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <glm/vec3.hpp>
#include <string>

#include "core/octree.h"

namespace vox {

// A ray in grid index space: voxel (i,j,k) is [i,i+1) x [j,j+1) x [k,k+1),
// the grid is [0, 2^N)^3. Points on the ray are origin + t * dir, t >= 0.
struct Ray {
  glm::dvec3 origin{0.0};
  glm::dvec3 dir{0.0, 0.0, 1.0};
};

// Refuses NaN or infinite components, a zero direction and an origin
// component beyond kMaxOriginMagnitude.
Status ValidateRay(const Ray& ray);

// The largest |origin component| a ray may have: 2^1000 (about 1.07e301),
// so the far-origin clipping's exact products stay finite.
inline constexpr double kMaxOriginMagnitude = 0x1p1000;

// Whether ValidateRay accepts the ray, without building a Status (the
// per-ray check of a traversal; ValidateRay says why when it does not).
inline bool IsValidRay(const Ray& ray) {
  bool ok = ray.dir.x != 0 || ray.dir.y != 0 || ray.dir.z != 0;
  for (int a = 0; a < 3; ++a)  // NaN fails both comparisons
    ok = ok && std::fabs(ray.origin[a]) <= kMaxOriginMagnitude &&
         std::fabs(ray.dir[a]) <= std::numeric_limits<double>::max();
  return ok;
}

// Origins farther than this many grid sizes from 0 on some axis are clipped
// by ClipFarRay: the usual clipping, t = (plane - o) / D in long double,
// loses the grid's extent next to |o| there.
inline constexpr double kFarOriginGrids = 256.0;
inline bool IsFarOrigin(const glm::dvec3& origin, double grid_size) {
  const double far = kFarOriginGrids * (grid_size > 1 ? grid_size : 1.0);
  return std::fabs(origin.x) > far || std::fabs(origin.y) > far || std::fabs(origin.z) > far;
}

// Clips a ray with a far origin (IsFarOrigin) to the grid [0, G]^3: sets the
// start point p, exactly on the entry face (other axes from an exact
// expansion of o_a D_d + (face - o_d) D_a, rounded once and divided by D_d),
// and the entry parameter. `D` is the scaled direction (ScaleDirection), `s`
// the travel signs. False when the ray does not meet the grid in a segment
// of positive length, as the usual clipping.
bool ClipFarRay(const glm::dvec3& origin, const double D[3], const int s[3], double G,
                long double p[3], long double* t_start);

struct Hit {
  glm::i64vec3 voxel{0};      // grid coordinates of the occupied voxel
  double t = 0.0;             // ray parameter where the ray enters it (0 if it starts inside)
  uint32_t brick = kNoBrick;  // the brick holding its payload, kNoBrick for the top pool
  uint32_t payload = 0;       // payload index in that pool
  // The brick's BrickView::data (nullptr for the top pool): valid while the
  // visitor that receives the hit runs (the traversal pins the brick).
  const void* brick_data = nullptr;
};

// A traversal visitor's answer to a hit, when `true` (go on) and `false`
// (stop) are not enough. kSkipBrick: go on after the hit's second-step grid
// (the first-step voxel it lies in) without reporting its other voxels, as
// after a second step without a hit; in a single-step walk it is kNext.
// SkipBlock(k): go on after the aligned block of 2^k voxels a side that holds
// the hit (voxel >> k), without reporting its other voxels: the walk leaves
// it by the skip loop's moves, as it leaves an empty octant of that size
// (in the second step's grid, or the first's for a block that is larger).
enum class Visit { kNext, kStop, kSkipBrick, kSkipBlock0 = 16 };
inline Visit AsVisit(bool go_on) { return go_on ? Visit::kNext : Visit::kStop; }
inline Visit AsVisit(Visit v) { return v; }
inline Visit SkipBlock(int levels) {
  return levels <= 0 ? Visit::kNext : Visit(int(Visit::kSkipBlock0) + levels);
}
// The k of SkipBlock(k), or 0 for the other answers.
inline int SkipBlockLevels(Visit v) {
  return int(v) > int(Visit::kSkipBlock0) ? int(v) - int(Visit::kSkipBlock0) : 0;
}

struct TraceCounters {
  uint64_t rays = 0;
  uint64_t moves[3] = {0, 0, 0};  // DDA moves along x, y, z
  uint64_t driving_moves = 0;     // moves along the ray's driving axis
  uint64_t passive_moves = 0;     // moves along the two other axes
  uint64_t skips = 0;          // empty octants (or missed first-step voxels) left by the skip loop
  uint64_t cells_visited = 0;  // child references read while descending
  uint64_t transitions = 0;    // second steps started
  uint64_t brick_fetches = 0;  // bricks asked of the BrickSource
  uint64_t hits = 0;

  uint64_t total_moves() const { return moves[0] + moves[1] + moves[2]; }
  void Add(const TraceCounters& o);
  std::string ToString() const;
};

// 2^e, exactly, without libm's ldexp for the exponents of normal doubles.
inline double Pow2(int e) {
  if (e < -1022 || e > 1023) return std::ldexp(1.0, e);
  const uint64_t bits = uint64_t(e + 1023) << 52;
  double d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

namespace internal {
// The ray parameter where the ray enters (entry) or leaves the closed voxel
// `v`: the last slab entry (at least 0) or the first slab exit.
inline double SlabT(const Ray& ray, const glm::i64vec3& v, bool entry) {
  double best = entry ? 0.0 : std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const double dir = ray.dir[a];
    if (dir == 0) continue;
    const bool pos = dir > 0;
    const double face = double(v[a]) + ((pos == entry) ? 0.0 : 1.0);
    const double t = (face - ray.origin[a]) / dir;
    best = entry ? std::max(best, t) : std::min(best, t);
  }
  return best;
}
}  // namespace internal

// Ray parameter where the ray enters the closed voxel `v` (clamped to >= 0),
// computed in double from the unscaled ray.
inline double VoxelEntryT(const Ray& ray, const glm::i64vec3& v) {
  return internal::SlabT(ray, v, true);
}
// Ray parameter where the ray leaves voxel `v`.
inline double VoxelExitT(const Ray& ray, const glm::i64vec3& v) {
  return internal::SlabT(ray, v, false);
}

}  // namespace vox

#endif  // VOX_CORE_RAY_H_

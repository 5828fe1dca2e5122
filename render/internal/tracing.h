// What the Renderer's files (renderer.cpp, surface.cpp, fog.cpp) share: the
// per-call context, the constants of the secondary rays, the loop over the
// lights that reach a point, and the state machine of a contiguous run of
// occupied voxels along a ray. Private to render/.
//
// Thread safety: OccupiedRun and Renderer::TraceContext belong to one call of one
// thread; the rest is stateless.
#ifndef VOX_RENDER_INTERNAL_TRACING_H_
#define VOX_RENDER_INTERNAL_TRACING_H_

#include <algorithm>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <limits>
#include <vector>

#include "core/ray.h"
#include "core/util/status.h"
#include "render/internal/fog_light.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "storage/brick_table.h"

namespace vox {

// Per-call state: the thread's tracer and counters, and the first error.
struct Renderer::TraceContext {
  const RenderTracer* tracer;
  RenderCounters* c;
  Status error;
  const LodThread* lod = nullptr;  // --lod: the thread's coarse tracers (optional)
  render_internal::FogLightCache* light_cache = nullptr;  // fog: the thread's (optional)
  // Where smooth normals read neighbouring voxels' bricks: the thread's
  // pinned-brick table, or the volume's source (null: the volume's).
  BrickSource* bricks = nullptr;
  bool failed() const { return !error.ok(); }
  void Fail(const Status& s) {
    if (error.ok()) error = s;
  }
};

// A render thread's own tracer and pinned-brick tables.
struct Renderer::ThreadState {
  std::unique_ptr<LendingBrickTable> bricks;
  RenderTracer tracer;
  std::unique_ptr<LodThread> lod;  // --lod: the coarse levels' tracers and table
  render_internal::FogLightCache light_cache;  // fog: the light on its lattice
};

// One primary sample's result (ShadePixel).
struct Renderer::Sample {
  glm::dvec3 color{0.0};
  double alpha = 0.0;
  double z = std::numeric_limits<double>::infinity();
  bool hit = false;
  int level = 0;  // with hit: the LOD level of the stop (0: a voxel)
  // Set with hit = true only (left unset otherwise: zeroing the whole
  // sample per ray cost 3% of a frame).
  glm::dvec3 normal;
  glm::i64vec3 voxel;
  double depth;         // planar camera depth of the hit (z * the view axis' cosine)
  glm::dvec3 position;  // world position of the hit
};

namespace render_internal {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
// Fog integration stops below this transmittance.
inline constexpr double kMinTransmittance = 1e-6;
// The optical depth of kMinTransmittance: -ln(1e-6) (compared per cell
// instead of the transmittance, which would cost an exp per cell).
inline constexpr double kMaxOpticalDepth = 13.815510557964274;
// Transmittance rays stop at this optical depth (a transmittance of 1e-3):
// the light they would still tell apart is below a thousandth of the
// light's own.
inline constexpr double kMaxShadowOpticalDepth = 6.907755278982137;
// The coarsest lattice fog's light is kept on: 2^10 voxels.
inline constexpr int kMaxLightLatticeLevel = 10;
// The first-step levels of a fog volume's traversal unless told otherwise:
// 5 instead of the surfaces' 6 (DefaultFirstStepLevels), so the second step
// covers at least 8^3 voxels on the grids of 2^8 and 2^9 measured
// (tools/bench/fog_bench.sh's frames: 5+3 and 5+4 were the fastest splits
// of 4, 5, 6 and single step, by 1-5%). Grids above 2^25 keep at most
// kMaxStepLevels per step.
inline int FogFirstStepLevels(int levels) {
  return std::max(levels - kMaxStepLevels, std::min(5, levels));
}

// Secondary rays leaving a surface start this many voxels out along its
// normal: a hit point lies within 1.9 voxels below and 0.9 above the true
// surface, and the voxels of the surface within 0.9 above it, so a ray
// lifted by 2.5 voxels clears the surface's own staircase even at grazing
// angles (no shadow or reflection acne). Occluders closer than that to the
// surface cast no shadow.
inline constexpr double kSurfaceOffsetVoxels = 2.5;

// Calls f(light, to_light, dist) for each light of positive intensity that
// has a direction at world point p: to_light is the unit direction to it and
// dist its distance (infinite for a directional light). A point light at p
// itself is skipped; one with falloff comes with its intensity divided by
// dist^2.
template <typename F>
void ForEachLight(const std::vector<Light>& lights, const glm::dvec3& p, F&& f) {
  for (const Light& l : lights) {
    if (l.intensity <= 0) continue;
    glm::dvec3 to_light;
    double dist = kInf;
    if (l.type == Light::Type::kDirectional) {
      to_light = -l.direction;
    } else {
      to_light = l.position - p;
      dist = glm::length(to_light);
      if (!(dist > 0)) continue;
      to_light /= dist;
      if (l.falloff) {
        Light reaching = l;
        reaching.intensity = l.intensity / (dist * dist);
        f(reaching, to_light, dist);
        continue;
      }
    }
    f(l, to_light, dist);
  }
}

// A run of occupied voxels along a ray: voxels each entered within eps of
// where the previous one was left (t tolerance eps * (1 + t)). Hits arrive
// in order; Extend adds one to the run, and Continues / EndedBefore tell
// whether the next hit touches the run or lies past an empty gap.
class OccupiedRun {
 public:
  // `started`: the ray starts inside a run (ending at t = 0 so far).
  OccupiedRun(double eps, bool started) : eps_(eps), active_(started) {}

  bool active() const { return active_; }
  // Where the run ends (the last voxel's exit t).
  double end() const { return end_; }
  // Hit h touches the run: it extends it.
  bool Continues(const Hit& h) const { return active_ && h.t <= end_ + eps_ * (1.0 + end_); }
  // Hit h lies past a gap after the run: the run ended before it.
  bool EndedBefore(const Hit& h) const { return active_ && h.t > end_ + eps_ * (1.0 + end_); }
  void Extend(const Ray& gr, const Hit& h) {
    active_ = true;
    end_ = VoxelExitT(gr, h.voxel);
  }

 private:
  double eps_;
  bool active_;
  double end_ = 0.0;
};

}  // namespace render_internal
}  // namespace vox

#endif  // VOX_RENDER_INTERNAL_TRACING_H_

// vox::LodTracer: ray cones over a level-of-detail pyramid (storage/lod.h;
// docs/lod.md). A ray carries a cone whose width at ray parameter t is
// Cone::Width(t) base voxels. With factor F, the level at t is the largest l
// with 2^l <= F * Width(t), clamped to the pyramid; it never decreases along
// the ray, so the ray is traced segment by segment: level l's coarse store
// (an ordinary store, traced by the paper's DDA unchanged) from where l
// begins to where l + 1 begins. A level-0 segment traces the base store with
// the ray itself, so where the level is 0 along the whole ray (Exact) the
// hits are exactly the full-resolution ones.
//
// Ray parameters: coarse segments trace the ray scaled by 2^-l from the
// segment's start; every t reported is the unscaled ray's.
//
// Thread safety: immutable after Create; Traverse and FirstHit are const and
// thread-safe when the volumes are (the base tracer is the caller's own).
#ifndef VOX_RENDER_LOD_H_
#define VOX_RENDER_LOD_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/ray.h"
#include "core/status.h"
#include "core/tracer.h"
#include "storage/store.h"

namespace vox {

// A cone's width along a ray: w0 + spread * t, in base voxels.
struct Cone {
  double w0 = 0.0;
  double spread = 0.0;  // base voxels per unit of the ray parameter
  double Width(double t) const { return w0 + spread * t; }
};

// Parses --lod's factor: a finite number > 0; errors name `flag`.
StatusOr<double> ParseLodFactor(const std::string& flag, const std::string& text);

// Counts of LOD stops (first hits) by level, and of rays traced exactly.
struct LodCounters {
  uint64_t stops[kMaxLevels + 1] = {};
  uint64_t exact_rays = 0;  // rays whose level stayed 0 within the volume
  void Add(const LodCounters& o) {
    for (int l = 0; l <= kMaxLevels; ++l) stops[l] += o.stops[l];
    exact_rays += o.exact_rays;
  }
};

// One occupied cell a LOD traversal meets.
struct LodSegment {
  int level = 0;        // 0: a base voxel
  Hit hit;              // as level `level`'s tracer reports it (voxel in that level's grid)
  double t0 = 0, t1 = 0;  // where the ray (unscaled) enters and leaves it, clipped to the segment
  Volume* volume = nullptr;  // level `level`'s volume (HitAttributes while visiting)
};

// The tracer of one coarse or base level.
using LodLevelTracer = AutoTracer<double>;

class LodTracer {
 public:
  // `levels[l - 1]` is level l's volume (levels 1 .. levels.size()); `base`
  // the base volume. `factor`: F > 0.
  static StatusOr<LodTracer> Create(Volume* base, const std::vector<Volume*>& levels,
                                    double factor);

  double factor() const { return factor_; }
  int max_level() const { return int(levels_.size()); }
  // The level for a cone of width `w` voxels: largest l with 2^l <= F w.
  int LevelForWidth(double w) const;
  // Whether the cone keeps level 0 wherever the ray meets the base volume's
  // occupied box: the LOD trace equals the full-resolution trace.
  bool Exact(const Ray& gr, const Cone& cone) const;

  // Visits the occupied cells along the ray in order, level by level,
  // until `visit` returns false. `base` traces level 0 (the caller's
  // tracer of the base volume, e.g. with a per-thread brick table).
  Status Traverse(const LodLevelTracer& base, const Ray& gr, const Cone& cone,
                  const std::function<bool(const LodSegment&)>& visit,
                  TraceCounters* counters = nullptr) const;

  // The first occupied cell along the ray, after the run of cells it starts
  // in when `skip_start_run` (cells each entered within eps * (1 + t) of
  // where the previous was left), with its attributes when `attrs`.
  // False on a miss.
  StatusOr<bool> FirstHit(const LodLevelTracer& base, const Ray& gr, const Cone& cone,
                          bool skip_start_run, double eps, LodSegment* out,
                          VoxelAttributes* attrs, TraceCounters* counters = nullptr) const;

 private:
  // Ray parameter where the level reaches l (infinite when it never does).
  double LevelStart(const Cone& cone, int l) const;
  // [t_in, t_out] of the ray in the base's occupied box (t_in > t_out: misses).
  void BoxSpan(const Ray& gr, double* t_in, double* t_out) const;

  Volume* base_ = nullptr;
  std::vector<Volume*> levels_;
  std::vector<LodLevelTracer> tracers_;  // of levels_
  double factor_ = 1.0;
  glm::dvec3 box_lo_{0.0}, box_hi_{-1.0};  // occupied box, base grid coordinates
};

}  // namespace vox

#endif  // VOX_RENDER_LOD_H_

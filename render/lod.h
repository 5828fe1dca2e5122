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
// Speed: a thread may bring its own LodThread (NewThread): its coarse levels'
// bricks then go through one small pinned-brick table of that thread
// (storage/brick_table.h) instead of the stores' shared caches, as the base
// store's do through the caller's tracer. Each level's tracer clips rays to
// its store's occupied box. Neither changes an answer.
//
// Thread safety: immutable after Create; Traverse and FirstHit are const and
// thread-safe when the volumes are (the base tracer and the LodThread are
// the caller's own).
#ifndef VOX_RENDER_LOD_H_
#define VOX_RENDER_LOD_H_

#include <algorithm>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/ray.h"
#include "core/util/status.h"
#include "core/tracer.h"
#include "render/camera.h"
#include "storage/brick_table.h"
#include "storage/store.h"

namespace vox {

// A cone's width along a ray: w0 + spread * t, in base voxels.
struct Cone {
  double w0 = 0.0;
  double spread = 0.0;  // base voxels per unit of the ray parameter
  double Width(double t) const { return w0 + spread * t; }
};

// The cone of `camera`'s primary rays, one pixel wide at the image plane,
// over a volume of voxel size `voxel_size` (world units): a perspective
// cone grows with the distance along the ray (camera rays are unit length
// in world units), an orthographic one does not.
Cone PrimaryConeOf(const Camera& camera, double voxel_size);

// Parses --lod's factor: a finite number >= 0 (0: the exact frame, no level
// of detail); errors name `flag`.
StatusOr<double> ParseLodFactor(const std::string& flag, const std::string& text);

// The factor vox-render uses when --lod is not given: 1 (a cell no wider
// than the pixel's cone) when the store has a pyramid, 0 (exact) without.
inline constexpr double kDefaultLodFactor = 1.0;

// Silhouette antialiasing of a LOD frame (Renderer, docs/lod.md): a pixel
// whose primary ray stops at a coarse cell next to a pixel whose ray misses
// is shaded again from G x G sub-pixel rays, each carrying a cone G times
// narrower; its alpha is the fraction of them that hit. The default G and
// its limits (--silhouette-aa G; 0: off).
inline constexpr int kDefaultSilhouetteGrid = 4;
inline constexpr int kMaxSilhouetteGrid = 8;

// Counts of LOD stops (first hits) by level, and of rays traced exactly.
struct LodCounters {
  uint64_t stops[kMaxLevels + 1] = {};
  uint64_t exact_rays = 0;  // rays whose level stayed 0 within the volume
  uint64_t refined_pixels = 0;  // silhouette pixels shaded again with sub-pixel rays
  uint64_t refine_rays = 0;     // their sub-pixel primary rays
  uint64_t border_rays = 0;     // rays of the neighbouring tiles' pixels, traced to classify
  void Add(const LodCounters& o) {
    for (int l = 0; l <= kMaxLevels; ++l) stops[l] += o.stops[l];
    exact_rays += o.exact_rays;
    refined_pixels += o.refined_pixels;
    refine_rays += o.refine_rays;
    border_rays += o.border_rays;
  }
};

// One occupied cell a LOD traversal meets.
struct LodSegment {
  int level = 0;        // 0: a base voxel
  Hit hit;              // as level `level`'s tracer reports it (voxel in that level's grid)
  double t0 = 0;        // where the ray (unscaled) enters it
  double t_end = 0;     // where the ray's segment at this level ends (infinite for the last)
  int n2 = 0;           // the second-step levels of this level's walk (Visit::kSkipBrick's reach)
  Volume* volume = nullptr;  // level `level`'s volume (HitAttributes while visiting)
  // Where the ray (unscaled) leaves the cell, clipped to the segment: computed
  // when asked, while visiting (a visitor that leaves a larger block never
  // needs it).
  double ExitT() const { return std::min(walk_t0 + VoxelExitT(*walk, hit.voxel), t_end); }

  const Ray* walk = nullptr;  // the level's walk: its ray (in that level's grid) ...
  double walk_t0 = 0;         // ... starts at this parameter of the unscaled ray
};

// The tracer of one coarse or base level.
using LodLevelTracer = AutoTracer<double>;

// Misses first: rays of `t` that pass outside the occupied box of the store
// described by `m` (widened by a voxel) are misses without a walk
// (Tracer::SetOccupiedBox); nothing for an empty store.
void ClipToOccupiedBox(const StoreMeta& m, LodLevelTracer* t);

class LodTracer;

// One thread's tracers of the coarse levels, their bricks lent by one
// pinned-brick table of 2^slot_bits slots shared by the levels. Use it on
// one thread; release it before the volumes.
class LodThread {
 public:
  ~LodThread();
  LodThread(const LodThread&) = delete;
  LodThread& operator=(const LodThread&) = delete;
  // Level l's tracer (1 <= l <= levels).
  const LodLevelTracer& level(int l) const { return tracers_[size_t(l - 1)]; }

 private:
  friend class LodTracer;
  LodThread() = default;
  class Levels;  // the table's shared source: tagged ids to the levels' stores
  class Tagged;  // one level's view of the table
  std::unique_ptr<Levels> levels_;
  std::unique_ptr<LendingBrickTable> table_;
  std::vector<std::unique_ptr<Tagged>> tagged_;
  std::vector<LodLevelTracer> tracers_;
};

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
  // The finest level a primary ray of `camera` (cone `cone`) can stop at, or
  // a secondary ray of its hits: the level of the cone where it is narrowest
  // within the world box [lo, hi] of the volume, at the box's point nearest
  // the camera (0 when the camera is inside).
  int FirstLevelSeen(const Camera& camera, const Cone& cone, const glm::dvec3& lo,
                     const glm::dvec3& hi) const;
  // Whether the cone keeps level 0 wherever the ray meets the base volume's
  // occupied box: the LOD trace equals the full-resolution trace.
  bool Exact(const Ray& gr, const Cone& cone) const;

  // A thread's own coarse tracers (see LodThread), with a table of
  // 2^slot_bits slots (clamped to 0..16). Levels whose brick ids do not
  // leave room for the table's level tag keep the shared tracers.
  std::unique_ptr<LodThread> NewThread(int slot_bits) const;

  // Visits the occupied cells along the ray in order, level by level,
  // until `visit` (bool(const LodSegment&), or Visit) returns false
  // (Visit::kStop; Visit::kSkipBrick skips the rest of the segment's
  // second-step grid, seg.n2 levels; SkipBlock(k) the rest of the cell's
  // block of 2^k cells of its level). `base` traces
  // level 0 (the caller's tracer of the base volume, e.g. with a per-thread
  // brick table); `thread` (optional) the coarse levels. `start` (may be
  // null): a beam StartPlane the ray satisfies in the base volume
  // (core/tracer.h); the level-0 segment's walk starts there, which changes
  // no answer. Coarse levels do not use it (a coarse cell is occupied where
  // the base has nothing), so an empty beam block's rays still walk them.
  template <class Visitor>
  Status Traverse(const LodLevelTracer& base, const LodThread* thread, const Ray& gr,
                  const Cone& cone, Visitor&& visit, TraceCounters* counters = nullptr,
                  const StartPlane* start = nullptr) const;

  // The first occupied cell along the ray, after the run of cells it starts
  // in when `skip_start_run` (cells each entered within eps * (1 + t) of
  // where the previous was left), with its attributes when `attrs`. (*out's
  // ExitT is not for use after the walk.)
  // False on a miss.
  StatusOr<bool> FirstHit(const LodLevelTracer& base, const LodThread* thread, const Ray& gr,
                          const Cone& cone, bool skip_start_run, double eps, LodSegment* out,
                          VoxelAttributes* attrs, TraceCounters* counters = nullptr,
                          const StartPlane* start = nullptr) const;

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
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

template <class Visitor>
Status LodTracer::Traverse(const LodLevelTracer& base, const LodThread* thread, const Ray& gr,
                           const Cone& cone, Visitor&& visit, TraceCounters* counters,
                           const StartPlane* start) const {
  double t_in, t_out;
  BoxSpan(gr, &t_in, &t_out);
  if (!(t_in <= t_out)) return OkStatus();
  const int top = max_level();
  double t_a = 0.0;
  int l = LevelForWidth(cone.Width(std::max(0.0, t_in)));
  while (l < top && LevelStart(cone, l + 1) <= t_a) ++l;
  bool stopped = false;  // the visitor said stop
  while (!stopped) {
    const double t_b = l < top ? LevelStart(cone, l + 1) : kInf;
    LodSegment seg;
    seg.level = l;
    seg.t_end = t_b;
    if (l == 0) {
      seg.volume = base_;
      seg.n2 = base.n2();
      seg.walk = &gr;
      seg.walk_t0 = 0.0;
      VOX_RETURN_IF_ERROR(base.Traverse(
          gr,
          [&](const Hit& h) {
            if (h.t >= t_b) return Visit::kStop;  // the segment ends
            seg.hit = h;
            seg.t0 = h.t;
            const Visit v = AsVisit(visit(seg));
            stopped = v == Visit::kStop;
            return v;
          },
          counters, start));
    } else {
      const double start = std::max(t_a, t_in);
      if (start >= t_out) break;
      const double s = Pow2(-l);
      const Ray cr{(gr.origin + start * gr.dir) * s, gr.dir * s};
      seg.volume = levels_[size_t(l - 1)];
      const LodLevelTracer& tracer =
          thread != nullptr ? thread->level(l) : tracers_[size_t(l - 1)];
      seg.n2 = tracer.n2();
      seg.walk = &cr;
      seg.walk_t0 = start;
      VOX_RETURN_IF_ERROR(tracer.Traverse(
          cr,
          [&](const Hit& h) {
            const double t0 = start + h.t;
            if (t0 >= t_b) return Visit::kStop;
            seg.hit = h;
            seg.t0 = t0;
            const Visit v = AsVisit(visit(seg));
            stopped = v == Visit::kStop;
            return v;
          },
          counters));
    }
    if (stopped || t_b >= t_out) break;
    t_a = t_b;
    ++l;
    while (l < top && LevelStart(cone, l + 1) <= t_a) ++l;
  }
  return OkStatus();
}

}  // namespace vox

#endif  // VOX_RENDER_LOD_H_

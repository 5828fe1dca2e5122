// The paper's two-step traversal (docs/algorithm.md, sections 1 and 4) as
// one driver for any DDA: validate the ray, set it up, walk the first step's
// grid, and in each occupied first-step voxel run the transition and walk the
// second step's grid, then report the hits and counters. vox::Tracer (the
// paper's fixed-point DDA) and the accuracy study's Amanatides-Woo tracer
// (tests/study/aw_tracer.h) both instantiate it and supply only their set-up,
// their step initialisation and their transition.
//
// Internal to core. Stateless function; thread-safe when the tree's
// BrickSource is.
#ifndef VOX_CORE_INTERNAL_TWO_STEP_WALK_H_
#define VOX_CORE_INTERNAL_TWO_STEP_WALK_H_

#include <cstdint>

#include "core/internal/octree_walk.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"

namespace vox::internal {

// Traces `ray` through `tree`, split into n1 first-step levels and n2 =
// tree.levels - n1 second-step levels (n2 == 0: a single step over the whole
// grid), calling `visit(const Hit&) -> bool` (or -> Visit) for each occupied
// voxel the ray meets, in order, until it returns false (Visit::kStop).
// Adds to `*counters` when given.
// Returns an error for an invalid ray or a brick that cannot be fetched.
//
// PerRay is one ray's state, made by the tracer for each call; it must provide
//   using Dda = ...;
//       a step's DDA state, as WalkStep wants it (`void Move(uint64_t& xyz)`).
//   bool Setup(const Ray& ray);
//       the per-ray set-up (direction scaling, axes, slopes, clipping to the
//       grid); false when the ray misses the grid (no hit, no error).
//   Dda FirstStep(const StepLayout& l1, uint64_t* xyz);
//       the first step's DDA state, and its start voxel packed per l1.
//   Dda SecondStep(const StepLayout& l1, const StepLayout& l2, uint64_t xyz,
//                  uint64_t prev, const Dda& first, uint64_t* xyz2);
//       the transition into occupied first-step voxel `xyz`: the second
//       step's DDA state, and its start voxel packed per l2. `prev` is the
//       first step's register before its last move (== xyz when the ray
//       starts in the voxel); `first` is the first step's state there.
//   void AddMoves(const Dda& dda, TraceCounters* c);
//       adds a finished step's move counts.
// After a second step without a hit, the first step goes on with its own
// state untouched.
template <class PerRay, class Visitor>
Status TraceTwoSteps(const OctreeView& tree, int n1, int n2, const Ray& ray, PerRay& per_ray,
                     Visitor& visit, TraceCounters* counters) {
  using Dda = typename PerRay::Dda;
  if (counters == nullptr) {  // (zeroing a local per ray costs when counters are kept)
    TraceCounters local;
    return TraceTwoSteps(tree, n1, n2, ray, per_ray, visit, &local);
  }
  if (!IsValidRay(ray)) [[unlikely]]
    return ValidateRay(ray);
  TraceCounters& c = *counters;
  ++c.rays;
  if (!per_ray.Setup(ray)) return OkStatus();
  const StepLayout l1(n1), l2(n2);
  uint64_t xyz1 = 0;
  Dda dda = per_ray.FirstStep(l1, &xyz1);
  BrickPinner pinner(tree.bricks, tree.top);
  const int top1 = TopBit(tree, n2), top2 = TopBit(tree, 0);
  WalkStats stats;
  const int64_t base0[3] = {0, 0, 0};
  // An occupied voxel of the last level: a hit.
  auto leaf = [&](const StepLayout& lay, const int64_t base[3], uint32_t child, bool in_brick,
                  uint64_t xyz) {
    Hit h = LeafHit(ray, lay, base, xyz, child, in_brick, pinner);
    const Flow f = FlowOf(AsVisit(visit(h)), /*skip_brick=*/n2 > 0);
    return f == Flow::kStop || pinner.Revalidate() ? f : Flow::kError;
  };
  auto occupied1 = [&](uint32_t child, uint64_t xyz, uint64_t prev, const Dda& d1) -> Flow {
    if (n2 == 0) return leaf(l1, base0, child, top1 > 0, xyz);
    // An occupied first-step voxel: trace the second step in it; a miss
    // there skips it and the first step goes on with its state untouched.
    CompactCell c2;
    if (!pinner.Resolve(child, 0, top1, c2)) return Flow::kError;
    ++c.transitions;
    uint64_t xyz2 = 0;
    Dda d2 = per_ray.SecondStep(l1, l2, xyz, prev, d1, &xyz2);
    const int64_t base2[3] = {l1.Coord(xyz, 0) << n2, l1.Coord(xyz, 1) << n2,
                              l1.Coord(xyz, 2) << n2};
    auto occupied2 = [&](uint32_t ch, uint64_t x2, uint64_t, const Dda&) {
      return leaf(l2, base2, ch, top2 > 0, x2);
    };
    Flow f = WalkStep(l2, xyz2, d2, c2, top2, pinner, occupied2, &stats);
    per_ray.AddMoves(d2, &c);
    // (skipped: the first step goes on; SkipFlow: it leaves the larger block)
    return f == Flow::kSkip ? Flow::kLeft : f;
  };
  Flow f = WalkStep(l1, xyz1, dda, tree.top[0], top1, pinner, occupied1, &stats);
  per_ray.AddMoves(dda, &c);
  return FinishWalk(f, stats, pinner, &c);
}

}  // namespace vox::internal

#endif  // VOX_CORE_INTERNAL_TWO_STEP_WALK_H_

// The two-step walk of two_step_walk.h as resumable state, so one thread can
// keep several rays in flight (issue 29 item 1; docs/benchmarks.md, "Several
// rays in flight"): each ray's walk runs until it needs a cell it has not
// read yet, prefetches that cell (or, at the top pool's last level, fetches
// the brick and prefetches its root) and hands the thread to the next ray,
// so the cache misses of several rays overlap (AMAC, Kocberber et al.,
// VLDB 2015). The arithmetic and the decisions are WalkStep's and
// TraceTwoSteps's, move for move: the same hits, bit for bit, and the same
// counters (tests/core/interleaved_walk_test.cpp checks both).
//
// Internal to core. Stateless functions over caller-owned state; thread-safe
// when the tree's BrickSource is.
#ifndef VOX_CORE_INTERNAL_WALK_STATE_H_
#define VOX_CORE_INTERNAL_WALK_STATE_H_

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <optional>

#include "core/internal/octree_walk.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/status.h"

namespace vox::internal {

// Most rays a thread keeps in flight.
inline constexpr int kMaxRaysInFlight = 16;

// What every ray of one traversal shares: the split and the steps' layouts.
struct WalkPlan {
  WalkPlan(const OctreeView& t, int first_levels, int second_levels)
      : tree(t),
        n1(first_levels),
        n2(second_levels),
        l1(first_levels),
        l2(second_levels),
        top1(TopBit(t, second_levels)),
        top2(TopBit(t, 0)) {}
  OctreeView tree;
  int n1, n2;
  StepLayout l1, l2;
  int top1, top2;  // the steps' TopBits
  // Hand over before reading a cell of the resident top pool too (false:
  // read those at once, hand over before brick cells only).
  bool yield_in_top = true;
};

// One step's walk (WalkStep's locals): the register, the register before the
// last move, the DDA, and the cell stack with its level.
template <class Dda>
struct StepWalk {
  uint64_t xyz = 0, prev = 0;
  Dda dda;
  int depth = 0, bit = 0;
  uint64_t mask = 0;
  CompactCell stack[kMaxStepLevels + 1];

  void Start(const StepLayout& lay, uint64_t start, const Dda& d, CompactCell root) {
    xyz = prev = start;
    dda = d;
    depth = 0;
    bit = lay.n - 1;
    mask = lay.unit << bit;
    stack[0] = root;
  }
};

// One ray's whole traversal state. PerRay as TraceTwoSteps wants it; it is
// built in place (`per_ray`) for each ray the slot takes.
template <class PerRay>
struct WalkState {
  using Dda = typename PerRay::Dda;
  enum class Phase : uint8_t {
    kWalk,   // walk the current step from its register (the step's start)
    kCell,   // `pending` is the child to push: descend on from it
    kRoot2,  // `pending` is the second step's root: transition, walk it
  };

  WalkState() = default;
  WalkState(const WalkState&) = delete;
  WalkState& operator=(const WalkState&) = delete;
  ~WalkState() { Clear(); }
  void Clear() {
    if (per_ray != nullptr) std::destroy_at(per_ray);
    per_ray = nullptr;
  }

  PerRay* per_ray = nullptr;  // in `storage`
  alignas(PerRay) unsigned char storage[sizeof(PerRay)];
  const Ray* ray = nullptr;
  size_t index = 0;  // the ray's position in the input
  BrickPinner pinner{nullptr, nullptr};
  StepWalk<Dda> s1, s2;
  int step = 1;  // the step being walked: 1, or 2 inside an occupied first-step voxel
  Phase phase = Phase::kWalk;
  const CompactCell* pending = nullptr;
  int64_t base2[3] = {0, 0, 0};  // the second step's grid corner, in finest voxels
  WalkStats stats;
};

// How a resumed walk stopped.
enum class Resumed { kPending, kHit, kMiss, kError };

// Advances ray `w` until it needs a cell it has not read: prefetches it and
// returns kPending; or to its end: kHit (*hit set), kMiss, or kError
// (w.pinner.error). Adds the ray's moves, skips, cells, transitions and
// fetches to `c` when it ends, as TraceTwoSteps does.
template <class PerRay>
Resumed Resume(const WalkPlan& plan, WalkState<PerRay>& w, Hit* hit, TraceCounters& c) {
  using Dda = typename PerRay::Dda;
  StepWalk<Dda>* s = w.step == 1 ? &w.s1 : &w.s2;
  const StepLayout* lay = w.step == 1 ? &plan.l1 : &plan.l2;
  int top_bit = w.step == 1 ? plan.top1 : plan.top2;
  int wd = lay->w;
  uint64_t carry = lay->carry;
  CompactCell cell;
  // The current step's scalars live in locals between a resume and a yield.
  uint64_t xyz = s->xyz, prev = s->prev, mask = s->mask;
  int depth = s->depth, bit = s->bit;
  auto save = [&] {
    s->xyz = xyz;
    s->prev = prev;
    s->mask = mask;
    s->depth = depth;
    s->bit = bit;
  };
  auto load = [&] {
    xyz = s->xyz;
    prev = s->prev;
    mask = s->mask;
    depth = s->depth;
    bit = s->bit;
  };
  // Makes step n (1 or 2) the current one and loads its scalars.
  auto enter_step = [&](int n) {
    w.step = n;
    s = n == 1 ? &w.s1 : &w.s2;
    lay = n == 1 ? &plan.l1 : &plan.l2;
    top_bit = n == 1 ? plan.top1 : plan.top2;
    wd = lay->w;
    carry = lay->carry;
    load();
  };
  auto finish = [&](Resumed r) {
    if (w.step == 2) w.per_ray->AddMoves(w.s2.dda, &c);
    w.per_ray->AddMoves(w.s1.dda, &c);
    c.skips += w.stats.skips;
    c.cells_visited += w.stats.cells;
    c.brick_fetches += w.pinner.fetches;
    return r;
  };
  // Hands the thread over until cell `p` (null: a fetch error) is read,
  // resuming in phase `next`.
  auto hand_over = [&](const CompactCell* p, typename WalkState<PerRay>::Phase next) {
    if (p == nullptr) return finish(Resumed::kError);
    __builtin_prefetch(p);
    save();
    w.pending = p;
    w.phase = next;
    return Resumed::kPending;
  };

  switch (w.phase) {
    case WalkState<PerRay>::Phase::kWalk:
      break;
    case WalkState<PerRay>::Phase::kCell:
      cell = *w.pending;
      ++depth;
      s->stack[depth] = cell;
      --bit;
      mask >>= 1;
      goto descend;
    case WalkState<PerRay>::Phase::kRoot2: {
      // The transition into occupied first-step voxel w.s1.xyz (TraceTwoSteps's occupied1).
      const CompactCell root2 = *w.pending;
      ++c.transitions;
      uint64_t xyz2 = 0;
      Dda d2 = w.per_ray->SecondStep(plan.l1, plan.l2, w.s1.xyz, w.s1.prev, w.s1.dda, &xyz2);
      for (int a = 0; a < 3; ++a) w.base2[a] = plan.l1.Coord(w.s1.xyz, a) << plan.n2;
      w.s2.Start(plan.l2, xyz2, d2, root2);
      enter_step(2);
      break;
    }
  }

  for (;;) {  // one step's walk (WalkStep); the second step's end goes back to the first
    while (!(xyz & carry)) {
      // Loop 3: descend until an empty octant or the step's last level.
      cell = s->stack[depth];
    descend:
      for (;;) {
        unsigned digit = unsigned((xyz >> bit) & 1) | unsigned(((xyz >> (wd + bit)) & 1) << 1) |
                         unsigned(((xyz >> (2 * wd + bit)) & 1) << 2);
        ++w.stats.cells;
        if (!HasChild(cell, digit)) break;
        const uint32_t child = ChildIndex(cell, digit);
        if (bit == 0) {
          if (w.step == 2 || plan.n2 == 0) {  // an occupied voxel of the last level: a hit
            const int64_t base0[3] = {0, 0, 0};
            const int top = w.step == 2 ? plan.top2 : plan.top1;
            *hit =
                LeafHit(*w.ray, *lay, w.step == 2 ? w.base2 : base0, xyz, child, top > 0, w.pinner);
            return finish(Resumed::kHit);
          }
          // An occupied first-step voxel: its second step's root, read on resuming.
          return hand_over(w.pinner.Locate(child, 0, plan.top1), WalkState<PerRay>::Phase::kRoot2);
        }
        if (bit > top_bit && !plan.yield_in_top) {  // the top pool: read it at once
          cell = plan.tree.top[child];
          ++depth;
          s->stack[depth] = cell;
          --bit;
          mask >>= 1;
          continue;
        }
        return hand_over(w.pinner.Locate(child, bit, top_bit), WalkState<PerRay>::Phase::kCell);
      }
    skip:
      // Skip: DDA moves until the octant's bit flips; no octree access.
      {
        const uint64_t start = xyz;
        Dda d = s->dda;
        do {
          prev = xyz;
          d.Move(xyz);
        } while (!((xyz ^ start) & mask));
        s->dda = d;
        ++w.stats.skips;
      }
      if (xyz & carry) break;
      // Loop 2: ascend once per level boundary crossed.
      while ((prev ^ xyz) & (mask << 1)) {
        --depth;
        ++bit;
        mask <<= 1;
      }
    }
    if (w.step == 1) return finish(Resumed::kMiss);
    // The second step found nothing: the first step goes on by its skip
    // loop, with its own state untouched.
    w.per_ray->AddMoves(w.s2.dda, &c);
    enter_step(1);
    goto skip;
  }
}

// The first hits of rays[0, n) into hits[0, n) (nullopt: a miss), as
// TraceTwoSteps with a visitor that stops at the first hit, keeping
// `in_flight` rays (1 to kMaxRaysInFlight) in flight round-robin and
// refilling a finished ray's slot from the input. Adds to `*counters` (when
// given) what FirstHitOf would add for each ray. `make(void* where, const
// Ray&)` constructs a PerRay for the ray at `where` and returns it.
// A source that lends its bricks (BrickSource::lends) keeps one lent brick
// at a time, so then one ray is in flight. Returns the first error met (an
// invalid ray, a brick that cannot be fetched); the hits are then partial.
template <class PerRay, class MakePerRay>
Status InterleavedFirstHits(const WalkPlan& plan, const Ray* rays, size_t n,
                            std::optional<Hit>* hits, int in_flight, MakePerRay&& make,
                            TraceCounters* counters) {
  TraceCounters local;
  TraceCounters& c = counters != nullptr ? *counters : local;
  const bool lending = plan.tree.bricks != nullptr && plan.tree.bricks->lends();
  const int k = lending ? 1 : std::clamp(in_flight, 1, kMaxRaysInFlight);
  WalkState<PerRay> slots[kMaxRaysInFlight];
  int order[kMaxRaysInFlight];  // live slots first
  size_t next = 0;
  Status error;
  // Puts the next ray that needs a walk into `w`; false when none is left.
  auto refill = [&](WalkState<PerRay>& w) {
    while (next < n) {
      const size_t i = next++;
      const Ray& ray = rays[i];
      hits[i].reset();
      if (!IsValidRay(ray)) [[unlikely]] {
        error = ValidateRay(ray);
        next = n;
        return false;
      }
      ++c.rays;
      w.Clear();
      w.per_ray = make(static_cast<void*>(w.storage), ray);
      if (!w.per_ray->Setup(ray)) continue;
      w.ray = &ray;
      w.index = i;
      w.pinner = BrickPinner(plan.tree.bricks, plan.tree.top);
      w.stats = WalkStats{};
      uint64_t xyz1 = 0;
      const typename PerRay::Dda d1 = w.per_ray->FirstStep(plan.l1, &xyz1);
      w.s1.Start(plan.l1, xyz1, d1, plan.tree.top[0]);
      w.step = 1;
      w.phase = WalkState<PerRay>::Phase::kWalk;
      return true;
    }
    return false;
  };
  int live = 0;
  while (live < k && refill(slots[live])) {
    order[live] = live;
    ++live;
  }
  for (int j = 0; live > 0;) {
    WalkState<PerRay>& w = slots[order[j]];
    Hit hit;
    const Resumed r = Resume(plan, w, &hit, c);
    if (r != Resumed::kPending) {
      if (r == Resumed::kHit) {
        hits[w.index] = hit;
        ++c.hits;
      } else if (r == Resumed::kError) {
        return w.pinner.error;
      }
      if (!refill(w)) {
        if (!error.ok()) return error;
        std::swap(order[j], order[live - 1]);
        --live;
        if (j < live) continue;  // the swapped-in slot runs next
      }
    }
    j = j + 1 < live ? j + 1 : 0;
  }
  return error;
}

}  // namespace vox::internal

#endif  // VOX_CORE_INTERNAL_WALK_STATE_H_

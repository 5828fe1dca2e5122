// The part of the paper's traversal (its figure 1; docs/algorithm.md,
// section 2) that does not depend on how a DDA does its arithmetic: descend
// (loop 3), the skip loop that leaves an empty octant by one bit test, and
// the ascent by XOR (loop 2), over a packed XYZ register with carry bits.
// Tracer (the paper's fixed-point DDA) and AwTracer (Amanatides-Woo, in the
// accuracy study's tests/study/aw_tracer.h) both run on it, through
// two_step_walk.h, so the two differ only in their arithmetic. Also the per-ray helpers they share:
// clipping to the grid, start voxels, brick pinning.
//
// Internal to core. Stateless functions; thread-safe.
#ifndef VOX_CORE_INTERNAL_OCTREE_WALK_H_
#define VOX_CORE_INTERNAL_OCTREE_WALK_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <type_traits>

#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"

namespace vox::internal {

// kSkip: a visitor's Visit::kSkipBrick, ending a second step's walk (or
// the rest of a step's grid). SkipFlow(k): a visitor's SkipBlock(k): a step
// leaves the hit's block of 2^k of its voxels by the skip loop and goes on,
// or, for a block at least as large as its grid, ends with kSkip (k equal to
// its levels n) or SkipFlow(k - n), for the step above to leave.
enum class Flow { kLeft, kStop, kError, kSkip, kSkipBlock0 = 16 };
inline Flow SkipFlow(int levels) { return Flow(int(Flow::kSkipBlock0) + levels); }

// A visitor's answer as a step's flow; `skip_brick`: kSkipBrick ends the
// step (else it is kLeft).
inline Flow FlowOf(Visit v, bool skip_brick) {
  if (v == Visit::kNext) [[likely]]
    return Flow::kLeft;
  if (v == Visit::kStop) return Flow::kStop;
  if (v == Visit::kSkipBrick) return skip_brick ? Flow::kSkip : Flow::kLeft;
  return SkipFlow(SkipBlockLevels(v));
}

// A step's packed-register geometry: x, y, z in fields of n + 1 bits.
struct StepLayout {
  int n = 0;  // levels of the step
  int w = 1;  // field width n + 1
  uint64_t unit = 0;   // bit 0 of each field
  uint64_t carry = 0;  // the three carry bits
  uint64_t field = 0;  // mask of one field's coordinate bits

  explicit StepLayout(int levels)
      : n(levels),
        w(levels + 1),
        unit(1 | (uint64_t(1) << w) | (uint64_t(1) << (2 * w))),
        carry(unit << levels),
        field((uint64_t(1) << levels) - 1) {}
  uint64_t Inc(int axis, int sign) const {
    return (uint64_t(1) << (axis * w)) * uint64_t(int64_t(sign));
  }
  uint64_t Pack(const int64_t v[3]) const {
    return uint64_t(v[0]) | (uint64_t(v[1]) << w) | (uint64_t(v[2]) << (2 * w));
  }
  int64_t Coord(uint64_t xyz, int axis) const { return int64_t((xyz >> (axis * w)) & field); }
  // The axis whose field differs between two registers one move apart.
  int MovedAxis(uint64_t diff) const {
    return (diff & (field | (field + 1))) ? 0 : (diff & ((field | (field + 1)) << w)) ? 1 : 2;
  }
};

// Where a step's top pool ends: cells at step bits >= the returned bit are
// top cells (those at exactly that bit have bricks as children), cells below
// it are brick cells. `levels_below` is the tree levels below the step's last
// level (n2 for the first step of two, else 0). -1 when there are no bricks:
// every cell is a top cell.
inline int TopBit(const OctreeView& tree, int levels_below) {
  return tree.brick_level < tree.levels ? (tree.levels - tree.brick_level) - levels_below : -1;
}

// Pins the brick a ray is in (at most one at a time: the stack never holds
// cells of two bricks) and resolves child indices to cells. A lending
// source (BrickSource::lends) keeps the brick pinned for it.
struct BrickPinner {
  BrickPinner(BrickSource* s, const CompactCell* top_pool)
      : source(s),
        lending(s != nullptr && s->lends()),
        epoch(lending ? s->lend_epoch() : nullptr),
        top(top_pool) {}

  BrickSource* source = nullptr;
  bool lending = false;
  const uint64_t* epoch = nullptr;  // the source's lend_epoch (lending only)
  uint64_t lent_at = 0;             // *epoch when the brick was lent
  const CompactCell* top = nullptr;    // the tree's top pool
  uint32_t id = kNoBrick;
  const CompactCell* cells = nullptr;  // the pinned brick's pool
  const void* data = nullptr;          // and its BrickView::data
  std::shared_ptr<const void> pin;     // when the source does not lend
  Status error{};
  uint64_t fetches = 0;

  // After a visit: when the source's loans may have ended meanwhile (a
  // visitor walked other rays through it), lends the pinned brick again so
  // that `cells` and `data` point into a live brick. False on a fetch error.
  bool Revalidate() {
    if (epoch == nullptr || *epoch == lent_at || id == kNoBrick) [[likely]]
      return true;
    const uint32_t want = id;
    id = kNoBrick;
    return Fetch(want);
  }

  // Sets `cell` to child `index` (ChildIndex) of a cell at step bit `bit`,
  // with `top_bit` the step's TopBit. False on a fetch error (kept in `error`).
  bool Resolve(uint32_t index, int bit, int top_bit, CompactCell& cell) {
    if (bit < top_bit) [[likely]] {
      cell = cells[index];
      return true;
    }
    if (bit > top_bit) {
      cell = top[index];
      return true;
    }
    if (index != id && !Fetch(index)) return false;
    cell = cells[0];
    return true;
  }

 private:
  bool Fetch(uint32_t want) {
    if (source == nullptr) {
      error = CorruptionError("octree refers to brick " + std::to_string(want) +
                              " but has no brick source");
      return false;
    }
    ++fetches;
    if (lending) {
      const BrickView* v = source->LendBrick(want, &error);
      if (v == nullptr) return false;
      cells = v->cells;
      data = v->data;
      if (epoch != nullptr) lent_at = *epoch;
    } else {
      auto b = source->FetchBrick(want);
      if (!b.ok()) {
        error = b.status();
        return false;
      }
      cells = b->cells;
      data = b->data;
      pin = std::move(b->pin);
    }
    id = want;
    return true;
  }
};

struct WalkStats {
  uint64_t skips = 0, cells = 0;
};

// The paper's figure 1 over one step's grid, starting in voxel `xyz` (packed per
// `layout`) with `root` the step's root cell and `top_bit` its TopBit.
//
// Dda must provide `void Move(uint64_t& xyz)`: one 6-connected move (adds
// +-1 to one field of xyz). `occupied(child, xyz, prev, dda) -> Flow` is
// called for a non-empty child at the step's last level, `child` its index
// (ChildIndex of the last-level cell: a payload at the tree's last level,
// else the next step's root for BrickPinner::Resolve at bit 0), with `prev`
// the register before the last move (== xyz before any move); kLeft goes on
// (the voxel is skipped), SkipFlow(k) goes on after the voxel's aligned
// block of 2^k voxels (k < layout.n; a larger block ends the walk, see
// Flow), kStop, kError and kSkip end the walk.
template <class Dda, class Occupied>
Flow WalkStep(const StepLayout& layout, uint64_t xyz, Dda& dda, CompactCell root, int top_bit,
              BrickPinner& pinner, Occupied&& occupied, WalkStats* stats) {
  const int w = layout.w;
  const uint64_t unit = layout.unit, carry = layout.carry;
  const int y_shift = w - 1, z_shift = 2 * w - 2;
  uint64_t prev = xyz;
  uint64_t skips = 0, cells = 0;
  Flow flow = Flow::kLeft;

  CompactCell cell_stack[kMaxStepLevels + 1];
  int depth = 0;
  cell_stack[0] = root;
  int bit = layout.n - 1;
  uint64_t mask = unit << bit;

  while (!(xyz & carry)) {
    // Loop 3: descend until an empty octant or the step's last level.
    CompactCell cell = cell_stack[depth];
    for (;;) {
      // (the octant's x, y, z bits at 0, w, 2w, then at 0, 1, 2)
      const uint64_t at = (xyz >> bit) & unit;
      const unsigned digit = unsigned((at & 1) | ((at >> y_shift) & 2) | ((at >> z_shift) & 4));
      ++cells;
      if (!HasChild(cell, digit)) break;
      const uint32_t child = ChildIndex(cell, digit);
      if (bit == 0) {
        flow = occupied(child, xyz, prev, dda);
        if (flow == Flow::kLeft) [[likely]]
          break;
        if (int(flow) <= int(Flow::kSkipBlock0)) goto done;
        const int k = int(flow) - int(Flow::kSkipBlock0);
        if (k >= layout.n) {  // the block holds the rest of this grid along the ray
          flow = k == layout.n ? Flow::kSkip : SkipFlow(k - layout.n);
          goto done;
        }
        // Leave the voxel's block of 2^k as an empty octant at bit k.
        flow = Flow::kLeft;
        depth -= k;
        bit = k;
        mask = unit << k;
        break;
      }
      if (!pinner.Resolve(child, bit, top_bit, cell)) {
        flow = Flow::kError;
        goto done;
      }
      ++depth;
      cell_stack[depth] = cell;
      --bit;
      mask >>= 1;
    }
    // Skip: DDA moves until the octant's bit flips; no octree access.
    // (On a local copy, so the DDA state lives in registers while moving.)
    {
      const uint64_t start = xyz;
      Dda d = dda;
      do {
        prev = xyz;
        d.Move(xyz);
      } while (!((xyz ^ start) & mask));
      dda = d;
      ++skips;
    }
    if (xyz & carry) break;
    // Loop 2: ascend once per level boundary crossed.
    while ((prev ^ xyz) & (mask << 1)) {
      --depth;
      ++bit;
      mask <<= 1;
    }
  }
done:
  stats->skips += skips;
  stats->cells += cells;
  return flow;
}

// The hit for occupied voxel `xyz` of a step's last level (step grid corner
// `base`, in finest voxels): coordinates, entry parameter, payload.
// `in_brick`: the voxel's pool is the pinner's brick (else the top pool).
inline Hit LeafHit(const Ray& ray, const StepLayout& lay, const int64_t base[3], uint64_t xyz,
                   uint32_t payload, bool in_brick, const BrickPinner& pinner) {
  Hit h;
  h.voxel = {base[0] + lay.Coord(xyz, 0), base[1] + lay.Coord(xyz, 1),
             base[2] + lay.Coord(xyz, 2)};
  h.t = VoxelEntryT(ray, h.voxel);
  h.brick = in_brick ? pinner.id : kNoBrick;
  h.payload = payload;
  h.brick_data = in_brick ? pinner.data : nullptr;
  return h;
}

// Adds a finished walk's counters and turns its flow into a Status.
inline Status FinishWalk(Flow flow, const WalkStats& stats, const BrickPinner& pinner,
                         TraceCounters* c) {
  c->skips += stats.skips;
  c->cells_visited += stats.cells;
  c->brick_fetches += pinner.fetches;
  return flow == Flow::kError ? pinner.error : OkStatus();
}

// FirstHit in terms of Traverse, for any tracer.
template <class TracerT>
StatusOr<std::optional<Hit>> FirstHitOf(const TracerT& tracer, const Ray& ray,
                                        TraceCounters* counters) {
  std::optional<Hit> result;
  Status s = tracer.Traverse(
      ray,
      [&](const Hit& h) {
        result = h;
        return false;
      },
      counters);
  if (!s.ok()) return s;
  if (result && counters) ++counters->hits;
  return result;
}

// Scales a direction by the power of two that puts its largest |component|
// in [1, 2): exact, keeps every ratio, and keeps ray parameters finite.
inline void ScaleDirection(const glm::dvec3& dir, double out[3]) {
  double m = std::max({std::fabs(dir.x), std::fabs(dir.y), std::fabs(dir.z)});
  uint64_t bits;
  std::memcpy(&bits, &m, sizeof bits);
  const int biased = int(bits >> 52) & 0x7ff;
  if (biased > 1 && biased < 0x7fe) {
    // m normal with exponent e = biased - 1023: multiply by the normal double
    // 2^-e (as exact as ldexp, without the libm call on every ray).
    const uint64_t scale_bits = uint64_t(2046 - biased) << 52;
    double scale;
    std::memcpy(&scale, &scale_bits, sizeof scale);
    for (int a = 0; a < 3; ++a) out[a] = dir[a] * scale;
    return;
  }
  int e = std::ilogb(m);  // subnormal or extreme magnitudes
  for (int a = 0; a < 3; ++a) out[a] = std::ldexp(dir[a], -e);
}

// Travel direction per axis: +1 when the unscaled component is >= 0
// (including -0), else -1. (Scaling can flush a subnormal component to +-0,
// and the ray still leaves its start plane to that side.)
inline int TravelSign(double unscaled) { return unscaled >= 0 ? 1 : -1; }

// Clips the ray o + t D (D scaled, s its travel signs) to the grid [0, G]^3:
// sets the start point p (the origin, or the entry point set exactly onto the
// entry face) and the entry parameter. False when the ray misses the grid.
template <class Real>
VOX_ALWAYS_INLINE bool ClipToGrid(const glm::dvec3& origin, const Real D[3], const int s[3], Real G,
                                  Real p[3], Real* t_start) {
  if constexpr (std::is_floating_point_v<Real>) {  // exact Reals need no help
    if (IsFarOrigin(origin, double(G))) {           // exact entry point (core/ray.h)
      const double Dd[3] = {double(D[0]), double(D[1]), double(D[2])};
      long double q[3], t;
      if (!ClipFarRay(origin, Dd, s, double(G), q, &t)) return false;
      for (int a = 0; a < 3; ++a) p[a] = Real(q[a]);
      *t_start = Real(t);
      return true;
    }
  }
  Real o[3] = {Real(origin.x), Real(origin.y), Real(origin.z)};
  Real t0 = Real(0), t1 = Real(0);
  bool bounded = false;
  int entry = -1;
  for (int a = 0; a < 3; ++a) {
    if (D[a] == Real(0)) {
      // Half-open along the axis, on the side the ray leaves o towards.
      if (s[a] > 0 ? (o[a] < Real(0) || o[a] >= G) : (o[a] <= Real(0) || o[a] > G)) return false;
      continue;
    }
    Real near = s[a] > 0 ? Real(0) : G, far = s[a] > 0 ? G : Real(0);
    Real ta = (near - o[a]) / D[a], tb = (far - o[a]) / D[a];
    if (ta > t0) {
      t0 = ta;
      entry = a;
    }
    if (!bounded || tb < t1) t1 = tb;
    bounded = true;
  }
  if (!(t1 > t0)) return false;
  for (int a = 0; a < 3; ++a) {
    if (entry < 0) {
      p[a] = o[a];
    } else if (a == entry) {
      p[a] = s[a] > 0 ? Real(0) : G;  // exactly on the entry face
    } else {
      p[a] = std::clamp(o[a] + t0 * D[a], Real(0), G);
    }
  }
  *t_start = t0;
  return true;
}

// Start voxel on one axis: the voxel the ray is in just after leaving p.
template <class Real>
VOX_ALWAYS_INLINE int64_t StartVoxel(Real p, int s, int64_t size) {
  if (!(p > Real(0))) return 0;  // also clamps p < 0 and catches NaN
  if (!(p < Real(size))) return size - 1;
  int64_t f = int64_t(p);  // floor, as p > 0
  int64_t v = s > 0 ? f : (Real(f) == p ? f - 1 : f);  // ceil(p) - 1 for s < 0
  return v < 0 ? 0 : v;
}

// The voxel the ray is in just *before* reaching p on one axis: differs from
// StartVoxel only when p lies exactly on a voxel boundary. The transition
// starts there on the axes of docs/algorithm.md, section 6.
template <class Real>
VOX_ALWAYS_INLINE int64_t BeforeVoxel(Real p, int s, int64_t size) {
  if (!(p > Real(0))) return 0;
  if (!(p < Real(size))) return size - 1;
  int64_t f = int64_t(p);  // floor, as p > 0
  int64_t v = s < 0 ? f : (Real(f) == p ? f - 1 : f);
  return v < 0 ? 0 : v;
}

}  // namespace vox::internal

#endif  // VOX_CORE_INTERNAL_OCTREE_WALK_H_

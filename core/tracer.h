// vox::Tracer: the paper's discrete ray traversal of an octree (Stolte &
// Caubet; restated in ../shared/design/algorithm.md): octree walk with the
// packed XYZ register and level mask, skip loop, ascent by XOR, the integer
// DDA in fixed point, and the two-step transition.
//
// Template requirements:
//   Fixed: a FixedPoint<Word, Frac> (fixed_point.h) with kIntBits >= 23, so
//          oriented coordinates and saturated slopes of a 20-level step fit.
//   Real:  float, double or long double: the type of the per-ray set-up
//          (clipping, first h and l) and of the transition's entry point.
//
// A Tracer is immutable once created: Traverse and FirstHit are const and may
// run concurrently on many threads if the tree's BrickSource is thread-safe.
// Each call keeps its own stack (no heap allocation) and pins at most one
// brick at a time.
#ifndef VOX_CORE_TRACER_H_
#define VOX_CORE_TRACER_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

#include "core/fixed_point.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/status.h"

namespace vox {

template <class Fixed = Fixed64, class Real = long double>
class Tracer {
 public:
  using Word = typename Fixed::Word;

  // n1 first-step levels; the second step gets levels - n1. n1 == levels is
  // the single-step traversal. Each step must have at most 20 levels.
  static StatusOr<Tracer> Create(const OctreeView& tree, int n1) {
    if (tree.levels < 1 || tree.levels > kMaxLevels || tree.top == nullptr)
      return InvalidArgumentError("octree has " + std::to_string(tree.levels) +
                                  " levels; vox traces 1 to 40");
    if (n1 < 1 || n1 > tree.levels)
      return InvalidArgumentError("first-step levels " + std::to_string(n1) + " outside 1.." +
                                  std::to_string(tree.levels));
    int n2 = tree.levels - n1;
    if (n1 > kMaxStepLevels || n2 > kMaxStepLevels)
      return InvalidArgumentError("split " + std::to_string(n1) + "+" + std::to_string(n2) +
                                  ": each step holds at most 20 levels" +
                                  (n2 == 0 ? " (single step needs a grid of at most 2^20)" : ""));
    int nmax = std::max(n1, n2);
    if (nmax + 3 > Fixed::kIntBits)
      return InvalidArgumentError("fixed-point format has " + std::to_string(Fixed::kIntBits) +
                                  " integer bits; a " + std::to_string(nmax) +
                                  "-level step needs " + std::to_string(nmax + 3));
    Tracer t;
    t.tree_ = tree;
    t.n1_ = n1;
    t.n2_ = n2;
    t.sat_ = Fixed::FromInt(int64_t(1) << (nmax + 2));
    t.sat_real_ = Fixed::template ToReal<Real>(t.sat_);
    t.down2_ = std::ldexp(Real(1), -n2);
    t.up2_ = std::ldexp(Real(1), n2);
    t.grid_size_ = std::ldexp(Real(1), tree.levels);
    return t;
  }

  int levels() const { return tree_.levels; }
  int n1() const { return n1_; }
  int n2() const { return n2_; }
  bool single_step() const { return n2_ == 0; }

  // Visits the occupied voxels the ray meets, in order along the ray, calling
  // `visit(const Hit&) -> bool` for each until it returns false. Returns an
  // error for an invalid ray or a brick that cannot be fetched.
  template <class Visitor>
  Status Traverse(const Ray& ray, Visitor&& visit, TraceCounters* counters = nullptr) const {
    VOX_RETURN_IF_ERROR(ValidateRay(ray));
    Ctx cx{ray};
    TraceCounters local;
    cx.counters = counters ? counters : &local;
    ++cx.counters->rays;
    if (!Setup(ray, &cx)) return OkStatus();
    Real p1[3];
    for (int a = 0; a < 3; ++a) p1[a] = cx.p[a] * down2_;
    Step st = InitStep(cx, p1, n1_);
    int64_t base[3] = {0, 0, 0};
    Flow f = Walk<true>(cx, st, n1_, tree_.top, tree_.top, visit, base);
    if (f == Flow::kError) return cx.error;
    return OkStatus();
  }

  // The first occupied voxel along the ray, or nullopt on a miss.
  StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* counters = nullptr) const {
    std::optional<Hit> result;
    Status s = Traverse(
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

 private:
  enum class Flow { kLeft, kStop, kError };

  // A step's DDA state: the packed register, the oriented driving coordinate
  // d', limit, and l1, l2.
  struct Step {
    uint64_t xyz = 0;
    int64_t dprime = 0, limit = 0;
    Word l1 = 0, l2 = 0;
  };

  // Per-ray state: the scaled ray, its axes and slopes, and the pinned brick.
  struct Ctx {
    const Ray& ray;
    Real D[3] = {};  // direction scaled so that max |D| is in [1, 2)
    Real p[3] = {};  // start point in voxel units: origin, or entry point on the grid
    int s[3] = {};   // travel direction per axis: +1 when D >= 0 (including -0), else -1
    int d = 0, i1 = 1, i2 = 2;  // driving axis and passive axes
    Word q1 = 0, q2 = 0;  // inverse slopes |D_d / D_i|, saturated
    Real q1r = 0, q2r = 0;
    bool ratios_ready = false;
    Real r1 = 0, r2 = 0;  // D_i / D_d, computed at the first transition
    uint32_t brick_id = kNoBrick;
    BrickView brick{};
    TraceCounters* counters = nullptr;
    Status error{};
  };

  // Scales the direction, picks the axes, computes the slopes and clips the
  // ray to the grid. Returns false when the ray misses the grid.
  bool Setup(const Ray& ray, Ctx* cx) const {
    double m = std::max({std::fabs(ray.dir.x), std::fabs(ray.dir.y), std::fabs(ray.dir.z)});
    int e = std::ilogb(m);
    double D[3];
    for (int a = 0; a < 3; ++a) {
      D[a] = std::ldexp(ray.dir[a], -e);  // exact: a power of two
      cx->D[a] = Real(D[a]);
      // The sign of the unscaled component: scaling can flush a subnormal
      // component to +-0.0 (dir (1e6, -5e-324, 0) scaled by 2^-19), and the
      // ray still leaves its start plane to that side.
      cx->s[a] = ray.dir[a] >= 0 ? 1 : -1;
    }
    // Driving axis: largest |D|, ties to the lower axis.
    int d = 0;
    for (int a = 1; a < 3; ++a)
      if (std::fabs(D[a]) > std::fabs(D[d])) d = a;
    cx->d = d;
    cx->i1 = d == 0 ? 1 : 0;
    cx->i2 = d == 2 ? 1 : 2;
    cx->q1 = Fixed::Ratio(D[d], D[cx->i1], sat_);
    cx->q2 = Fixed::Ratio(D[d], D[cx->i2], sat_);
    // The first boundary crossing of a passive axis, l = d + h * q, needs the
    // true slope even when q saturates: h can be small enough to bring a
    // crossing with q >= sat inside the grid. Later crossings (l += q) are
    // one whole voxel apart and lie beyond the grid once q saturates.
    cx->q1r = cx->q1 < sat_ ? Fixed::template ToReal<Real>(cx->q1)
                            : std::fabs(Real(D[d]) / Real(D[cx->i1]));  // inf if D_i1 == 0
    cx->q2r = cx->q2 < sat_ ? Fixed::template ToReal<Real>(cx->q2)
                            : std::fabs(Real(D[d]) / Real(D[cx->i2]));

    // Clip to [0, G]^3 (closed; the half-open voxel rule is applied by the
    // start-voxel choice). t is in units of the scaled direction.
    const Real G = grid_size_;
    Real o[3] = {Real(ray.origin.x), Real(ray.origin.y), Real(ray.origin.z)};
    Real t0 = 0, t1 = std::numeric_limits<Real>::infinity();
    int entry = -1;
    for (int a = 0; a < 3; ++a) {
      if (D[a] == 0) {
        // Half-open along the axis, on the side the ray leaves o towards.
        if (cx->s[a] > 0 ? (o[a] < 0 || o[a] >= G) : (o[a] <= 0 || o[a] > G)) return false;
        continue;
      }
      Real near = cx->s[a] > 0 ? 0 : G, far = cx->s[a] > 0 ? G : 0;
      Real ta = (near - o[a]) / cx->D[a], tb = (far - o[a]) / cx->D[a];
      if (ta > t0) {
        t0 = ta;
        entry = a;
      }
      t1 = std::min(t1, tb);
    }
    if (!(t1 > t0)) return false;
    for (int a = 0; a < 3; ++a) {
      if (entry < 0) {
        cx->p[a] = o[a];
      } else if (a == entry) {
        cx->p[a] = cx->s[a] > 0 ? 0 : G;  // exactly on the entry face
      } else {
        cx->p[a] = std::clamp(o[a] + t0 * cx->D[a], Real(0), G);
      }
    }
    return true;
  }

  // Start voxel on one axis: the voxel the ray is in just after leaving p.
  static int64_t StartVoxel(Real p, int s, int64_t size) {
    if (!(p > 0)) return 0;            // also clamps p < 0 and catches NaN
    if (!(p < Real(size))) return size - 1;
    int64_t f = int64_t(p);            // floor, as p > 0
    int64_t v = s > 0 ? f : (Real(f) == p ? f - 1 : f);  // ceil(p) - 1 for s < 0
    return v < 0 ? 0 : v;
  }

  // The voxel the ray is in just *before* reaching p on one axis: differs
  // from StartVoxel only when p lies exactly on a voxel boundary. The second
  // step starts there on axes whose crossing the single-step DDA would make
  // after the move that entered C (its tie order: d, then i1, then i2), so
  // both modes visit the same voxels at exact lattice crossings.
  static int64_t BeforeVoxel(Real p, int s, int64_t size) {
    if (!(p > 0)) return 0;
    if (!(p < Real(size))) return size - 1;
    int64_t f = int64_t(p);  // floor, as p > 0
    int64_t v = s < 0 ? f : (Real(f) == p ? f - 1 : f);
    return v < 0 ? 0 : v;
  }

  // Distance from p to the next boundary of voxel v in the direction of travel.
  static Real H(Real p, int64_t v, int s) {
    Real h = s > 0 ? Real(v + 1) - p : p - Real(v);
    return std::clamp(h, Real(0), Real(1));
  }

  // ud + h * q in fixed point, saturated.
  // `qr` is the unsaturated slope; h * qr may be NaN (0 * inf): saturated.
  Word LValue(Real ud, Real h, Word /*q*/, Real qr) const {
    Real l = ud + h * qr;
    if (!(l < sat_real_)) return sat_;
    return Fixed::FromReal(l);
  }

  static uint64_t Pack(const int64_t v[3], int n) {
    int w = n + 1;
    return uint64_t(v[0]) | (uint64_t(v[1]) << w) | (uint64_t(v[2]) << (2 * w));
  }

  // Section 4: a step's DDA state from a start point in the step's units.
  // Axes in the bit mask `before` take BeforeVoxel instead of StartVoxel.
  Step InitStep(const Ctx& cx, const Real p[3], int n, unsigned before = 0) const {
    int64_t size = int64_t(1) << n;
    int64_t v[3];
    for (int a = 0; a < 3; ++a)
      v[a] = (before >> a) & 1 ? BeforeVoxel(p[a], cx.s[a], size)
                               : StartVoxel(p[a], cx.s[a], size);
    Step st;
    Real ud = cx.s[cx.d] * p[cx.d];
    st.dprime = cx.s[cx.d] > 0 ? v[cx.d] : -v[cx.d] - 1;
    st.l1 = LValue(ud, H(p[cx.i1], v[cx.i1], cx.s[cx.i1]), cx.q1, cx.q1r);
    st.l2 = LValue(ud, H(p[cx.i2], v[cx.i2], cx.s[cx.i2]), cx.q2, cx.q2r);
    st.limit = Fixed::Floor(std::min(st.l1, st.l2));
    st.xyz = Pack(v, n);
    return st;
  }

  // Section 5: the second step's state on entering first-step voxel C.
  // `prev` is XYZ before the last first-step move (== xyz when none).
  Step Transition(Ctx& cx, uint64_t xyz, uint64_t prev, Word l1, Word l2) const {
    const int n1 = n1_, n2 = n2_, w1 = n1 + 1;
    const int64_t size2 = int64_t(1) << n2;
    const uint64_t field = (uint64_t(1) << n1) - 1;
    int64_t C[3];
    for (int a = 0; a < 3; ++a) C[a] = int64_t((xyz >> (a * w1)) & field);
    const int d = cx.d, s_d = cx.s[d];
    uint64_t diff = xyz ^ prev;
    Real p2[3];
    if (diff == 0) {
      // Case A: the ray starts in C.
      for (int a = 0; a < 3; ++a) p2[a] = cx.p[a] - Real(C[a] << n2);
      return InitStep(cx, p2, n2);
    }
    if (!cx.ratios_ready) {
      cx.r1 = cx.D[cx.i1] / cx.D[d];
      cx.r2 = cx.D[cx.i2] / cx.D[d];
      cx.ratios_ready = true;
    }
    Real p1[3];
    for (int a = 0; a < 3; ++a) p1[a] = cx.p[a] * down2_;
    int moved = (diff & field_mask(w1, 0)) ? 0 : (diff & field_mask(w1, 1)) ? 1 : 2;
    if (moved == d) {
      // Case B: entry through the face perpendicular to d.
      Real face = Real(C[d] + (s_d > 0 ? 0 : 1));
      Real dd = face - p1[d];
      p2[d] = s_d > 0 ? Real(0) : Real(size2);
      p2[cx.i1] = (p1[cx.i1] + dd * cx.r1 - Real(C[cx.i1])) * up2_;
      p2[cx.i2] = (p1[cx.i2] + dd * cx.r2 - Real(C[cx.i2])) * up2_;
      // On a passive boundary exactly at the face, the single-step DDA moves
      // along d first: start before that boundary, if the ray did arrive
      // there (its coordinate moved since the start point; one that did not,
      // e.g. a zero or 1e-300 component, keeps its start side).
      unsigned before = 0;
      for (int a : {cx.i1, cx.i2})
        if (p2[a] != cx.p[a] - Real(C[a] << n2)) before |= 1u << a;
      return InitStep(cx, p2, n2, before);
    }
    // Case C: entry through the face perpendicular to passive axis c, where
    // the first step crossed it (its l before the increment), in fixed point.
    const bool c_is_1 = moved == cx.i1;
    const int c = moved, o = c_is_1 ? cx.i2 : cx.i1;
    const Word lc_old = c_is_1 ? l1 - cx.q1 : l2 - cx.q2;
    const Word u2 = (lc_old - Fixed::FromInt(s_d * C[d])) * (Word(1) << n2);
    const int64_t lo = s_d > 0 ? 0 : -size2;
    Step st;
    st.dprime = std::clamp(Fixed::Floor(u2), lo, lo + size2 - 1);
    int64_t v[3];
    v[d] = s_d > 0 ? st.dprime : -st.dprime - 1;
    v[c] = cx.s[c] > 0 ? 0 : size2 - 1;
    Real xd1 = s_d * Fixed::template ToReal<Real>(lc_old);  // entry d, first-step units
    Real p_o = (p1[o] + (xd1 - p1[d]) * (c_is_1 ? cx.r2 : cx.r1) - Real(C[o])) * up2_;
    // On a boundary of the other passive axis exactly at the entry, the
    // single-step DDA has crossed it already if it is i1 (i1 before i2).
    // (An axis along which the ray has not moved keeps its start side.)
    v[o] = c_is_1 && p_o != cx.p[o] - Real(C[o] << n2) ? BeforeVoxel(p_o, cx.s[o], size2)
                                                        : StartVoxel(p_o, cx.s[o], size2);
    const Word qc = c_is_1 ? cx.q1 : cx.q2;
    const Word lc = qc >= sat_ ? sat_ : u2 + qc;
    const Word lo_w = LValue(Fixed::template ToReal<Real>(u2), H(p_o, v[o], cx.s[o]),
                             c_is_1 ? cx.q2 : cx.q1, c_is_1 ? cx.q2r : cx.q1r);
    st.l1 = c_is_1 ? lc : lo_w;
    st.l2 = c_is_1 ? lo_w : lc;
    st.limit = Fixed::Floor(std::min(st.l1, st.l2));
    st.xyz = Pack(v, n2);
    return st;
  }

  static constexpr uint64_t field_mask(int w, int a) {
    return ((uint64_t(1) << w) - 1) << (a * w);
  }

  // Resolves a child reference to its cell and pool, fetching a brick when
  // the reference names one.
  bool Resolve(Ctx& cx, NodeRef child, const Cell*& cell, const Cell*& pool) const {
    if (!IsBrickRef(child)) {
      cell = pool + child;
      return true;
    }
    uint32_t id = child & kBrickIdMask;
    if (id != cx.brick_id) {
      if (tree_.bricks == nullptr) {
        cx.error = CorruptionError("octree refers to brick " + std::to_string(id) +
                                   " but has no brick source");
        return false;
      }
      ++cx.counters->brick_fetches;
      auto b = tree_.bricks->FetchBrick(id);
      if (!b.ok()) {
        cx.error = b.status();
        return false;
      }
      cx.brick = std::move(b).value();
      cx.brick_id = id;
    }
    pool = cx.brick.cells;
    cell = pool;
    return true;
  }

  // Figure 1: one step's traversal from its root cell. `base` is the finest
  // voxel coordinate of the step grid's corner.
  template <bool kFirst, class Visitor>
  Flow Walk(Ctx& cx, Step& st, int n, const Cell* root, const Cell* root_pool, Visitor& visit,
            const int64_t base[3]) const {
    const int w = n + 1;
    const uint64_t unit = 1 | (uint64_t(1) << w) | (uint64_t(1) << (2 * w));
    const uint64_t carry = unit << n;
    const int d = cx.d, i1 = cx.i1, i2 = cx.i2;
    const uint64_t inc_d = (uint64_t(1) << (d * w)) * uint64_t(int64_t(cx.s[d]));
    const uint64_t inc_1 = (uint64_t(1) << (i1 * w)) * uint64_t(int64_t(cx.s[i1]));
    const uint64_t inc_2 = (uint64_t(1) << (i2 * w)) * uint64_t(int64_t(cx.s[i2]));
    const Word q1 = cx.q1, q2 = cx.q2;

    uint64_t xyz = st.xyz, prev = st.xyz;
    int64_t dprime = st.dprime, limit = st.limit;
    Word l1 = st.l1, l2 = st.l2;
    uint64_t nd = 0, np1 = 0, np2 = 0, skips = 0, cells = 0;
    Flow flow = Flow::kLeft;

    const Cell* cell_stack[kMaxStepLevels + 1];
    const Cell* pool_stack[kMaxStepLevels + 1];
    int depth = 0;
    cell_stack[0] = root;
    pool_stack[0] = root_pool;
    int bit = n - 1;
    uint64_t mask = unit << bit;

    while (!(xyz & carry)) {
      // Loop 3: descend until an empty octant or the step's last level.
      const Cell* cell = cell_stack[depth];
      const Cell* pool = pool_stack[depth];
      for (;;) {
        unsigned digit = unsigned((xyz >> bit) & 1) | unsigned(((xyz >> (w + bit)) & 1) << 1) |
                         unsigned(((xyz >> (2 * w + bit)) & 1) << 2);
        NodeRef child = cell->child[digit];
        ++cells;
        if (child == kEmptyRef) break;
        if (bit == 0) {
          if constexpr (kFirst) {
            if (n2_ > 0) {
              // An occupied first-step voxel: trace the second step in it.
              const Cell* c2 = nullptr;
              const Cell* p2 = pool;
              if (!Resolve(cx, child, c2, p2)) {
                flow = Flow::kError;
                goto done;
              }
              Step st2 = Transition(cx, xyz, prev, l1, l2);
              ++cx.counters->transitions;
              const uint64_t f = (uint64_t(1) << n) - 1;
              int64_t base2[3] = {int64_t(xyz & f) << n2_, int64_t((xyz >> w) & f) << n2_,
                                  int64_t((xyz >> (2 * w)) & f) << n2_};
              Flow f2 = Walk<false>(cx, st2, n2_, c2, p2, visit, base2);
              if (f2 != Flow::kLeft) {
                flow = f2;
                goto done;
              }
              break;  // missed inside: skip this first-step voxel
            }
          }
          // An occupied voxel: a hit.
          const uint64_t f = (uint64_t(1) << n) - 1;
          Hit h;
          h.voxel = {base[0] + int64_t(xyz & f), base[1] + int64_t((xyz >> w) & f),
                     base[2] + int64_t((xyz >> (2 * w)) & f)};
          h.t = VoxelEntryT(cx.ray, h.voxel);
          h.brick = pool == tree_.top ? kNoBrick : cx.brick_id;
          h.payload = LeafPayload(child);
          if (!visit(h)) {
            flow = Flow::kStop;
            goto done;
          }
          break;
        }
        if (!Resolve(cx, child, cell, pool)) {
          flow = Flow::kError;
          goto done;
        }
        ++depth;
        cell_stack[depth] = cell;
        pool_stack[depth] = pool;
        --bit;
        mask >>= 1;
      }
      // Skip: DDA moves until the octant's bit flips; no octree access.
      {
        const uint64_t start = xyz;
        do {
          prev = xyz;
          if (dprime < limit) {
            ++dprime;
            xyz += inc_d;
            ++nd;
          } else {
            if (l1 <= l2) {
              xyz += inc_1;
              l1 += q1;
              ++np1;
            } else {
              xyz += inc_2;
              l2 += q2;
              ++np2;
            }
            limit = Fixed::Floor(l1 < l2 ? l1 : l2);
          }
        } while (!((xyz ^ start) & mask));
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
    TraceCounters& c = *cx.counters;
    c.moves[d] += nd;
    c.moves[i1] += np1;
    c.moves[i2] += np2;
    c.driving_moves += nd;
    c.passive_moves += np1 + np2;
    c.skips += skips;
    c.cells_visited += cells;
    return flow;
  }

  OctreeView tree_;
  int n1_ = 0, n2_ = 0;
  Word sat_ = 0;
  Real sat_real_ = 0;
  Real down2_ = 1, up2_ = 1;  // 2^-n2, 2^n2: first-step <-> second-step units
  Real grid_size_ = 0;        // 2^levels
};

// The first-step levels vox uses unless told otherwise: the paper's best
// split has 6 first-step levels; grids of up to 2^6 are traced in one step,
// and each step keeps at most 20 levels.
inline int DefaultFirstStepLevels(int levels) {
  return std::max(levels - kMaxStepLevels, std::min(6, levels));
}

// Parses "N1+N2" (which must add up to `levels`) or "N1" into first-step levels.
StatusOr<int> ParseSplit(const std::string& text, int levels);

// The tracer vox uses unless told otherwise.
using DefaultTracer = Tracer<Fixed64, long double>;

}  // namespace vox

#endif  // VOX_CORE_TRACER_H_

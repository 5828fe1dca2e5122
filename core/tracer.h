// vox::Tracer: the paper's discrete ray traversal of an octree (Stolte &
// Caubet; described in docs/algorithm.md): octree walk with the packed XYZ
// register and level mask, skip loop, ascent by XOR (internal/octree_walk.h),
// the two steps (internal/two_step_walk.h), and here the per-ray set-up, the
// integer DDA in fixed point and the two-step transition.
//
// Template requirements:
//   Fixed: a FixedPoint<Word, Frac> (fixed_point.h) with kIntBits >= 23, so
//          oriented coordinates and saturated slopes of a 20-level step fit.
//   Real:  float, double, long double, or an exact type with the same
//          operators, fabs, floor and ldexp (the accuracy study's ExactReal,
//          tests/study/exact_real.h): the type of the per-ray set-up
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
#include <variant>

#include "core/fixed_point.h"
#include "core/internal/octree_walk.h"
#include "core/internal/two_step_walk.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"

namespace vox {

// A start hint for Traverse (beam start distances: render/beam.h computes one
// per block of pixels from the resident top). The caller promises: every
// point P of the ray (grid coordinates) with dot(g, P) < s_min lies more than
// kStartPlaneMargin voxels (on some axis) away from every occupied cell of
// the first step's grid (tree level n1; a coarser occupied cell counts for
// all its first-step cells). Then the ray's first-step DDA jumps, in exact
// integer arithmetic, to the state it would have on entering the last
// driving slab before the plane, and the walk goes on from there: the same
// voxels, hits and t as without the hint, bit for bit (docs/performance.md).
// s_min == +inf: the ray meets no occupied voxel at all (a miss, no walk).
struct StartPlane {
  double g[3] = {0, 0, 0};
  double s_min = -std::numeric_limits<double>::infinity();
};
inline constexpr double kStartPlaneMargin = 1.0;

// OkStatus when `tree` can be traced in two steps of n1 and levels - n1
// levels: 1 to 40 levels with a top, a brick level inside them, and each step
// at most kMaxStepLevels (20) levels. Every tracer's Create checks it first.
inline Status CheckTwoStepSplit(const OctreeView& tree, int n1) {
  if (tree.levels < 1 || tree.levels > kMaxLevels || tree.top == nullptr)
    return InvalidArgumentError("octree has " + std::to_string(tree.levels) +
                                " levels; vox traces 1 to 40");
  if (tree.brick_level < 1 || tree.brick_level > tree.levels)
    return InvalidArgumentError("octree brick level " + std::to_string(tree.brick_level) +
                                " outside 1.." + std::to_string(tree.levels));
  if (n1 < 1 || n1 > tree.levels)
    return InvalidArgumentError("first-step levels " + std::to_string(n1) + " outside 1.." +
                                std::to_string(tree.levels));
  const int n2 = tree.levels - n1;
  if (n1 > kMaxStepLevels || n2 > kMaxStepLevels)
    return InvalidArgumentError("split " + std::to_string(n1) + "+" + std::to_string(n2) +
                                ": each step holds at most 20 levels" +
                                (n2 == 0 ? " (single step needs a grid of at most 2^20)" : ""));
  return OkStatus();
}

template <class Fixed = Fixed64, class Real = long double>
class Tracer {
 public:
  using Word = typename Fixed::Word;

  // n1 first-step levels; the second step gets levels - n1. n1 == levels is
  // the single-step traversal. Each step must have at most 20 levels.
  static StatusOr<Tracer> Create(const OctreeView& tree, int n1) {
    VOX_RETURN_IF_ERROR(CheckTwoStepSplit(tree, n1));
    int n2 = tree.levels - n1;
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
    using std::ldexp;
    t.down2_ = ldexp(Real(1), -n2);
    t.up2_ = ldexp(Real(1), n2);
    t.grid_size_ = ldexp(Real(1), tree.levels);
    return t;
  }

  // Misses first: grid voxels [lo, hi] (inclusive) hold every occupied voxel
  // of the tree (a store's exact occupied bbox). A ray that passes outside
  // that box, widened by kBoxMargin voxels on every side, is a miss at once,
  // without a walk. The widened test is conservative (its rounding errors are
  // far below a voxel for any ray the tracer accepts), so it drops only rays
  // that meet no occupied voxel: every hit stays as the walk finds it (rays
  // from far origins, IsFarOrigin, are always walked). And each step's DDA
  // starts at the box: it jumps over the driving slabs before the box's
  // first layer (BoxSlab, JumpToSlab), in both steps, in exact integers, so the walk
  // meets the same voxels with the same hits and t.
  void SetOccupiedBox(const int64_t lo[3], const int64_t hi[3]) {
    has_box_ = true;
    for (int a = 0; a < 3; ++a) {
      box_lo_i_[a] = lo[a];
      box_hi_i_[a] = hi[a];
      box_lo_[a] = double(lo[a]) - kBoxMargin;
      box_hi_[a] = double(hi[a]) + 1.0 + kBoxMargin;
    }
  }
  void ClearOccupiedBox() { has_box_ = false; }
  bool has_occupied_box() const { return has_box_; }
  static constexpr double kBoxMargin = 1.0;

  int levels() const { return tree_.levels; }
  int n1() const { return n1_; }
  int n2() const { return n2_; }
  bool single_step() const { return n2_ == 0; }

  // Visits the occupied voxels the ray meets, in order along the ray, calling
  // `visit(const Hit&) -> bool` (or -> Visit, core/ray.h) for each until it
  // returns false (Visit::kStop). Returns an
  // error for an invalid ray or a brick that cannot be fetched.
  // `start` (may be null): a StartPlane the ray satisfies.
  template <class Visitor>
  Status Traverse(const Ray& ray, Visitor&& visit, TraceCounters* counters = nullptr,
                  const StartPlane* start = nullptr) const {
    PerRay r{*this, ScaledRay{ray}, start};
    return internal::TraceTwoSteps(tree_, n1_, n2_, ray, r, visit, counters);
  }

  // The first occupied voxel along the ray, or nullopt on a miss.
  StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* counters = nullptr) const {
    return internal::FirstHitOf(*this, ray, counters);
  }

 private:
  // A step's DDA state (docs/algorithm.md, section 3; the paper's figures 4
  // and 5): the oriented driving coordinate d', limit, l1 and l2, the per-ray
  // slopes and increments, and move counters.
  struct Dda {
    int64_t dprime = 0, limit = 0;
    Word l1 = 0, l2 = 0;
    Word q1 = 0, q2 = 0;
    uint64_t inc_d = 0, inc_1 = 0, inc_2 = 0;
    uint64_t nd = 0, n1 = 0, n2 = 0;

    // One move: along d when no passive boundary lies in the current voxel
    // (d' < limit), else along the passive axis crossed first (ties: i1).
    void Move(uint64_t& x) {
      if (dprime < limit) {
        ++dprime;
        x += inc_d;
        ++nd;
        return;
      }
      if (l1 <= l2) {
        x += inc_1;
        l1 += q1;
        ++n1;
      } else {
        x += inc_2;
        l2 += q2;
        ++n2;
      }
      limit = Fixed::Floor(l1 < l2 ? l1 : l2);
    }
    template <class RayT>
    void AddTo(const RayT& cx, TraceCounters* c) const {
      c->moves[cx.d] += nd;
      c->moves[cx.i1] += n1;
      c->moves[cx.i2] += n2;
      c->driving_moves += nd;
      c->passive_moves += n1 + n2;
    }
  };

  // Per-ray state: the scaled ray, its axes and slopes.
  // Setup sets every field before any use (and a ray it refuses is not
  // walked), so the constructor leaves them unset: zeroing them cost a
  // measurable share of a frame's per-ray work.
  struct ScaledRay {
    explicit ScaledRay(const Ray& r) : ray(r) {}
    const Ray& ray;
    Real D[3];  // direction scaled so that max |D| is in [1, 2)
    Real p[3];  // start point in voxel units: origin, or entry point on the grid
    int s[3];   // travel direction per axis: +1 when D >= 0 (including -0), else -1
    int d, i1, i2;  // driving axis and passive axes
    Word q1, q2;    // inverse slopes |D_d / D_i|, saturated
    Real q1r, q2r;
    bool ratios_ready = false;
    Real r1, r2;  // D_i / D_d, computed at the first transition
  };

  // One ray's state and arithmetic for internal::TraceTwoSteps.
  struct PerRay {
    using Dda = Tracer::Dda;
    const Tracer& t;
    ScaledRay cx;
    const StartPlane* start = nullptr;

    VOX_ALWAYS_INLINE bool Setup(const Ray& ray) {
      if (start != nullptr && start->s_min == std::numeric_limits<double>::infinity())
        return false;  // the ray's whole beam meets no occupied cell
      return t.Setup(ray, &cx);
    }
    VOX_ALWAYS_INLINE Dda FirstStep(const internal::StepLayout& l1, uint64_t* xyz) {
      Real p1[3];
      for (int a = 0; a < 3; ++a) p1[a] = cx.p[a] * t.down2_;
      Dda st = t.InitStep(cx, l1, p1, xyz);
      // One jump to the later of the beam plane's and the box's slabs (a
      // jump to slab A, then to slab B >= A, is the jump to B).
      int64_t target = std::numeric_limits<int64_t>::min();
      if (start != nullptr && !t.PlaneSlab(cx, l1, p1, *start, &target)) {
        *xyz = l1.carry;  // the ray leaves the grid before the plane: a miss
        return st;
      }
      if (t.has_box_) target = std::max(target, t.BoxSlab(cx, t.n2_, 0));
      JumpToSlab(cx, l1, target, &st, xyz);
      return st;
    }
    VOX_ALWAYS_INLINE Dda SecondStep(const internal::StepLayout& l1, const internal::StepLayout& l2,
                                     uint64_t xyz, uint64_t prev, const Dda& first,
                                     uint64_t* xyz2) {
      Dda st = t.Transition(cx, l1, l2, xyz, prev, first, xyz2);
      if (t.has_box_) JumpToSlab(cx, l2, t.BoxSlab(cx, 0, l1.Coord(xyz, cx.d) << t.n2_), &st, xyz2);
      return st;
    }
    void AddMoves(const Dda& dda, TraceCounters* c) const { dda.AddTo(cx, c); }
  };

  // Scales the direction, picks the axes, computes the slopes and clips the
  // ray to the grid. Returns false when the ray misses the grid.
  VOX_ALWAYS_INLINE bool Setup(const Ray& ray, ScaledRay* cx) const {
    using std::fabs;
    double D[3];
    internal::ScaleDirection(ray.dir, D);
    if (has_box_ && !MeetsBox(ray.origin, D)) return false;
    for (int a = 0; a < 3; ++a) {
      cx->D[a] = Real(D[a]);
      cx->s[a] = internal::TravelSign(ray.dir[a]);
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
                            : fabs(Real(D[d]) / Real(D[cx->i1]));  // inf if D_i1 == 0
    cx->q2r = cx->q2 < sat_ ? Fixed::template ToReal<Real>(cx->q2)
                            : fabs(Real(D[d]) / Real(D[cx->i2]));
    Real t_start;
    return internal::ClipToGrid(ray.origin, cx->D, cx->s, grid_size_, cx->p, &t_start);
  }

  // Whether the ray from `o` along D meets the widened occupied box (t >= 0).
  // Far origins (IsFarOrigin) are not tested: their slabs lose the box's
  // extent next to |o| in double. A NaN slab (0 * inf) constrains nothing.
  VOX_ALWAYS_INLINE bool MeetsBox(const glm::dvec3& o, const double D[3]) const {
    if (IsFarOrigin(o, double(grid_size_))) return true;
    double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      if (D[a] == 0.0) {
        if (o[a] < box_lo_[a] || o[a] > box_hi_[a]) return false;
        continue;
      }
      const double inv = 1.0 / D[a];
      double ta = (box_lo_[a] - o[a]) * inv, tb = (box_hi_[a] - o[a]) * inv;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    return t0 <= t1;
  }

  // Distance from p to the next boundary of voxel v in the direction of travel.
  VOX_ALWAYS_INLINE static Real H(Real p, int64_t v, int s) {
    Real h = s > 0 ? Real(v + 1) - p : p - Real(v);
    return std::clamp(h, Real(0), Real(1));
  }

  // ud + h * q in fixed point, saturated.
  // `qr` is the unsaturated slope; h * qr may be NaN (0 * inf): saturated.
  VOX_ALWAYS_INLINE Word LValue(Real ud, Real h, Real qr) const {
    Real l = ud + h * qr;
    if (!(l < sat_real_)) return sat_;
    return Fixed::FromReal(l);
  }

  // docs/algorithm.md, section 3: a step's DDA state from a start point in
  // the step's units, and its start voxel packed per `lay`. Axes in the bit
  // mask `before` take BeforeVoxel instead of StartVoxel.
  VOX_ALWAYS_INLINE Dda InitStep(const ScaledRay& cx, const internal::StepLayout& lay,
                                 const Real p[3], uint64_t* xyz, unsigned before = 0) const {
    int64_t size = int64_t(1) << lay.n;
    int64_t v[3];
    for (int a = 0; a < 3; ++a)
      v[a] = (before >> a) & 1 ? internal::BeforeVoxel(p[a], cx.s[a], size)
                               : internal::StartVoxel(p[a], cx.s[a], size);
    Dda st = NewDda(cx, lay);
    Real ud = cx.s[cx.d] * p[cx.d];
    st.dprime = cx.s[cx.d] > 0 ? v[cx.d] : -v[cx.d] - 1;
    st.l1 = LValue(ud, H(p[cx.i1], v[cx.i1], cx.s[cx.i1]), cx.q1r);
    st.l2 = LValue(ud, H(p[cx.i2], v[cx.i2], cx.s[cx.i2]), cx.q2r);
    st.limit = Fixed::Floor(std::min(st.l1, st.l2));
    *xyz = lay.Pack(v);
    return st;
  }

  // Beam start (StartPlane): the oriented driving slab of the first step
  // (units of `lay`, start point p1) one before the slab where the ray
  // meets the plane, into *target when the plane lies ahead. With l_i0 and
  // q_i a passive axis's first crossing and slope, the DDA enters slab D (a
  // driving move) once it has made exactly the k_i crossings with l_i0 +
  // k q_i < D: all integers, so JumpToSlab's state is exact. Every
  // first-step voxel the walk meets before it lies before the plane, so is
  // empty, and the walk from there visits the same voxels as from the
  // start. False when the ray leaves the grid before the plane (a miss).
  VOX_ALWAYS_INLINE bool PlaneSlab(const ScaledRay& cx, const internal::StepLayout& lay,
                                   const Real p1[3], const StartPlane& sp, int64_t* target) const {
    double s0 = 0, gd = 0;
    for (int a = 0; a < 3; ++a) {
      s0 += sp.g[a] * double(cx.p[a]);
      gd += sp.g[a] * double(cx.D[a]);
    }
    if (!(sp.s_min > s0) || !(gd > 0)) return true;
    const int d = cx.d, sd = cx.s[d];
    const int64_t size = int64_t(1) << lay.n;
    // The plane's driving coordinate, oriented, in first-step units.
    const double tau = (sp.s_min - s0) / gd;
    const double ud = sd * (double(p1[d]) + tau * double(cx.D[d]) * double(down2_));
    const double end = sd > 0 ? double(size) : 0.0;  // the grid's far face, oriented
    if (!(ud < end + 2.0)) return !(ud >= end + 2.0);  // leaves the grid first (or NaN)
    *target = std::max(*target, int64_t(std::floor(ud)) - 1);
    return true;
  }

  // Moves a step's DDA `st` (voxel *xyz, per `lay`) to the state it has on
  // entering oriented driving slab `target`, if that lies ahead, in exact
  // integer arithmetic (see PlaneSlab); the moves it stands for are
  // counted. A ray that leaves the step's grid before that slab: *xyz gets
  // the carry bits (the walk ends at once).
  VOX_ALWAYS_INLINE static void JumpToSlab(const ScaledRay& cx, const internal::StepLayout& lay,
                                           int64_t target, Dda* st, uint64_t* xyz) {
    if (target <= st->dprime || (*xyz & lay.carry)) return;  // (carry: the walk has ended)
    const int d = cx.d, sd = cx.s[d];
    const int64_t size = int64_t(1) << lay.n;
    const int64_t moved = target - st->dprime;
    int64_t v[3];
    for (int a = 0; a < 3; ++a) v[a] = lay.Coord(*xyz, a);
    const Word dw = Fixed::FromInt(target);
    Word l[2] = {st->l1, st->l2};
    const Word q[2] = {st->q1, st->q2};
    uint64_t k[2] = {0, 0};
    for (int i = 0; i < 2; ++i) {
      if (l[i] >= dw) continue;
      const Word n = (dw - l[i] + q[i] - 1) / q[i];  // smallest k with l + k q >= D
      k[i] = uint64_t(n);
      l[i] += n * q[i];
    }
    v[d] = sd > 0 ? target : -target - 1;
    v[cx.i1] += cx.s[cx.i1] * int64_t(k[0]);
    v[cx.i2] += cx.s[cx.i2] * int64_t(k[1]);
    for (int a = 0; a < 3; ++a)
      if (v[a] < 0 || v[a] >= size) {  // left the grid before slab D
        *xyz = lay.carry;
        return;
      }
    st->dprime = target;
    st->l1 = l[0];
    st->l2 = l[1];
    st->limit = Fixed::Floor(std::min(st->l1, st->l2));
    st->nd += uint64_t(moved);
    st->n1 += k[0];
    st->n2 += k[1];
    *xyz = lay.Pack(v);
  }

  // The box jump (SetOccupiedBox): every voxel outside the occupied box is
  // empty, so a step's DDA may jump (JumpToSlab) to the driving slab just
  // before the box's first layer along its travel (the slab it lands in is
  // empty, so the walk meets the same voxels from there). A step voxel is
  // 2^shift grid voxels, and its voxel 0 lies at grid coordinate `base`
  // along the driving axis. Returns that oriented slab.
  VOX_ALWAYS_INLINE int64_t BoxSlab(const ScaledRay& cx, int shift, int64_t base) const {
    const int d = cx.d;
    return cx.s[d] > 0 ? (box_lo_i_[d] >> shift) - base - 1
                       : -((box_hi_i_[d] >> shift) - base + 1) - 1;
  }

  // A step's DDA with the ray's slopes and the step's increments.
  VOX_ALWAYS_INLINE static Dda NewDda(const ScaledRay& cx, const internal::StepLayout& lay) {
    Dda st;
    st.q1 = cx.q1;
    st.q2 = cx.q2;
    st.inc_d = lay.Inc(cx.d, cx.s[cx.d]);
    st.inc_1 = lay.Inc(cx.i1, cx.s[cx.i1]);
    st.inc_2 = lay.Inc(cx.i2, cx.s[cx.i2]);
    return st;
  }

  // docs/algorithm.md, section 4: the second step's state on entering
  // first-step voxel C (cases A, B, C; the start voxels on exact boundaries
  // follow section 6).
  // `prev` is XYZ before the last first-step move (== xyz when none). Sets
  // *xyz2 to the second step's start voxel.
  VOX_ALWAYS_INLINE Dda Transition(ScaledRay& cx, const internal::StepLayout& lay1,
                                   const internal::StepLayout& lay2, uint64_t xyz, uint64_t prev,
                                   const Dda& first, uint64_t* xyz2) const {
    const int n2 = n2_;
    const int64_t size2 = int64_t(1) << n2;
    int64_t C[3];
    for (int a = 0; a < 3; ++a) C[a] = lay1.Coord(xyz, a);
    const int d = cx.d, s_d = cx.s[d];
    uint64_t diff = xyz ^ prev;
    Real p2[3];
    if (diff == 0) {
      // Case A: the ray starts in C.
      for (int a = 0; a < 3; ++a) p2[a] = cx.p[a] - Real(C[a] << n2);
      return InitStep(cx, lay2, p2, xyz2);
    }
    if (!cx.ratios_ready) {
      cx.r1 = cx.D[cx.i1] / cx.D[d];
      cx.r2 = cx.D[cx.i2] / cx.D[d];
      cx.ratios_ready = true;
    }
    Real p1[3];
    for (int a = 0; a < 3; ++a) p1[a] = cx.p[a] * down2_;
    int moved = lay1.MovedAxis(diff);
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
      return InitStep(cx, lay2, p2, xyz2, before);
    }
    // Case C: entry through the face perpendicular to passive axis c, where
    // the first step crossed it (its l before the increment), in fixed point.
    const bool c_is_1 = moved == cx.i1;
    const int c = moved, o = c_is_1 ? cx.i2 : cx.i1;
    const Word lc_old = c_is_1 ? first.l1 - cx.q1 : first.l2 - cx.q2;
    const Word u2 = (lc_old - Fixed::FromInt(s_d * C[d])) * (Word(1) << n2);
    const int64_t lo = s_d > 0 ? 0 : -size2;
    Dda st = NewDda(cx, lay2);
    st.dprime = std::clamp(Fixed::Floor(u2), lo, lo + size2 - 1);
    int64_t v[3];
    v[d] = s_d > 0 ? st.dprime : -st.dprime - 1;
    v[c] = cx.s[c] > 0 ? 0 : size2 - 1;
    Real xd1 = s_d * Fixed::template ToReal<Real>(lc_old);  // entry d, first-step units
    Real p_o = (p1[o] + (xd1 - p1[d]) * (c_is_1 ? cx.r2 : cx.r1) - Real(C[o])) * up2_;
    // On a boundary of the other passive axis exactly at the entry, the
    // single-step DDA has crossed it already if it is i1 (i1 before i2).
    // (An axis along which the ray has not moved keeps its start side.)
    v[o] = c_is_1 && p_o != cx.p[o] - Real(C[o] << n2)
               ? internal::BeforeVoxel(p_o, cx.s[o], size2)
               : internal::StartVoxel(p_o, cx.s[o], size2);
    const Word qc = c_is_1 ? cx.q1 : cx.q2;
    const Word lc = qc >= sat_ ? sat_ : u2 + qc;
    const Word lo_w =
        LValue(Fixed::template ToReal<Real>(u2), H(p_o, v[o], cx.s[o]), c_is_1 ? cx.q2r : cx.q1r);
    st.l1 = c_is_1 ? lc : lo_w;
    st.l2 = c_is_1 ? lo_w : lc;
    st.limit = Fixed::Floor(std::min(st.l1, st.l2));
    *xyz2 = lay2.Pack(v);
    return st;
  }

  OctreeView tree_;
  int n1_ = 0, n2_ = 0;
  Word sat_ = 0;
  Real sat_real_ = 0;
  Real down2_ = 1, up2_ = 1;  // 2^-n2, 2^n2: first-step <-> second-step units
  Real grid_size_ = 0;        // 2^levels
  bool has_box_ = false;      // SetOccupiedBox: the widened occupied box
  double box_lo_[3] = {}, box_hi_[3] = {};
  int64_t box_lo_i_[3] = {}, box_hi_i_[3] = {};  // and the box itself (inclusive)
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

// Deepest octree whose traversal stays exact with a 64-bit word: each passive
// move adds up to 2^-40 of slope error, so l drifts by about 2^(levels - 39)
// voxels at worst (tests/core measure it: 2.7% wrong first hits on rays
// crossing a 2^40 grid, none up to 2^20, a few within 0.001 voxel at 2^30).
inline constexpr int kFixed64MaxLevels = 26;

// The paper's tracer with the word chosen for the grid: Fixed64 up to
// kFixed64MaxLevels levels, Fixed128 (exact on every grid the tests reach,
// slower per ray: docs/accuracy.md) above. Same interface as Tracer.
template <class Real = long double>
class AutoTracer {
 public:
  using Narrow = Tracer<Fixed64, Real>;
  using Wide = Tracer<Fixed128, Real>;

  static StatusOr<AutoTracer> Create(const OctreeView& tree, int n1) {
    AutoTracer t;
    if (tree.levels <= kFixed64MaxLevels) {
      auto n = Narrow::Create(tree, n1);
      if (!n.ok()) return n.status();
      t.t_ = *n;
    } else {
      auto w = Wide::Create(tree, n1);
      if (!w.ok()) return w.status();
      t.t_ = *w;
    }
    return t;
  }

  int levels() const { return std::visit([](const auto& t) { return t.levels(); }, t_); }
  int n1() const { return std::visit([](const auto& t) { return t.n1(); }, t_); }
  int n2() const { return std::visit([](const auto& t) { return t.n2(); }, t_); }
  bool single_step() const { return n2() == 0; }
  int word_bits() const { return t_.index() == 0 ? 64 : 128; }
  void SetOccupiedBox(const int64_t lo[3], const int64_t hi[3]) {
    std::visit([&](auto& t) { t.SetOccupiedBox(lo, hi); }, t_);
  }
  bool has_occupied_box() const {
    return std::visit([](const auto& t) { return t.has_occupied_box(); }, t_);
  }

  template <class Visitor>
  Status Traverse(const Ray& ray, Visitor&& visit, TraceCounters* counters = nullptr,
                  const StartPlane* start = nullptr) const {
    return std::visit([&](const auto& t) { return t.Traverse(ray, visit, counters, start); }, t_);
  }
  StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* counters = nullptr) const {
    return std::visit([&](const auto& t) { return t.FirstHit(ray, counters); }, t_);
  }

 private:
  std::variant<Narrow, Wide> t_;
};

}  // namespace vox

#endif  // VOX_CORE_TRACER_H_

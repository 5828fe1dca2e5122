// vox::AwTracer: the floating-point 3D DDA of Amanatides and Woo ("A Fast
// Voxel Traversal Algorithm for Ray Tracing", 1987), the alternative the
// paper argued against, for the accuracy/time study. It walks the octree
// exactly as Tracer does (the same two-step driver, descend, skip loop and
// ascent: core/internal/two_step_walk.h), but chooses each move by comparing
// floating-point ray parameters tMax += tDelta instead of the paper's
// fixed-point l += q (docs/algorithm.md, section 3), and enters the second
// step from the floating-point entry parameter.
//
// Template requirement: Real is float, double or long double.
// Thread safety: immutable; Traverse and FirstHit are const and thread-safe
// when the tree's BrickSource is.
#ifndef VOX_TESTS_STUDY_AW_TRACER_H_
#define VOX_TESTS_STUDY_AW_TRACER_H_

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>

#include "core/internal/octree_walk.h"
#include "core/internal/two_step_walk.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"
#include "core/tracer.h"

namespace vox {

template <class Real>
class AwTracer {
 public:
  static StatusOr<AwTracer> Create(const OctreeView& tree, int n1) {
    VOX_RETURN_IF_ERROR(CheckTwoStepSplit(tree, n1));  // core/tracer.h
    const int n2 = tree.levels - n1;
    AwTracer t;
    t.tree_ = tree;
    t.n1_ = n1;
    t.n2_ = n2;
    return t;
  }

  int n1() const { return n1_; }
  int n2() const { return n2_; }

  template <class Visitor>
  Status Traverse(const Ray& ray, Visitor&& visit, TraceCounters* counters = nullptr) const {
    PerRay r{*this, Ctx{ray}};
    return internal::TraceTwoSteps(tree_, n1_, n2_, ray, r, visit, counters);
  }

  StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* counters = nullptr) const {
    return internal::FirstHitOf(*this, ray, counters);
  }

 private:
  struct Ctx {
    const Ray& ray;
    Real D[3] = {}, o[3] = {}, p[3] = {};
    int s[3] = {};
    Real t_start = 0;
    Real s1 = 1;  // a first-step voxel's size in finest voxels, 2^n2
  };

  // Amanatides-Woo state: per axis, the parameter of the next boundary and
  // the parameter between boundaries.
  struct Dda {
    Real tmax[3], tdelta[3];
    uint64_t inc[3];
    uint64_t moves[3] = {0, 0, 0};
    void Move(uint64_t& xyz) {
      int a = tmax[0] <= tmax[1] ? (tmax[0] <= tmax[2] ? 0 : 2) : (tmax[1] <= tmax[2] ? 1 : 2);
      xyz += inc[a];
      tmax[a] += tdelta[a];
      ++moves[a];
    }
  };

  // One ray's state and arithmetic for internal::TraceTwoSteps.
  struct PerRay {
    using Dda = AwTracer::Dda;
    const AwTracer& t;
    Ctx cx;

    bool Setup(const Ray& ray) {
      double D[3];
      internal::ScaleDirection(ray.dir, D);
      for (int a = 0; a < 3; ++a) {
        cx.D[a] = Real(D[a]);
        cx.s[a] = internal::TravelSign(ray.dir[a]);
        cx.o[a] = Real(ray.origin[a]);
      }
      const Real G = std::ldexp(Real(1), t.tree_.levels);
      return internal::ClipToGrid(ray.origin, cx.D, cx.s, G, cx.p, &cx.t_start);
    }

    // First step: voxels of 2^n2 finest voxels.
    Dda FirstStep(const internal::StepLayout& l1, uint64_t* xyz) {
      cx.s1 = std::ldexp(Real(1), t.n2_);
      int64_t v[3];
      for (int a = 0; a < 3; ++a)
        v[a] = internal::StartVoxel(cx.p[a] / cx.s1, cx.s[a], int64_t(1) << t.n1_);
      const int64_t base0[3] = {0, 0, 0};
      *xyz = l1.Pack(v);
      return MakeDda(cx, l1, v, base0, cx.s1);
    }

    // Entry into first-step voxel C: the start point when the ray starts in
    // C, else the largest near-face parameter of C.
    Dda SecondStep(const internal::StepLayout& l1, const internal::StepLayout& l2, uint64_t xyz,
                   uint64_t prev, const Dda&, uint64_t* xyz2) {
      const int n2 = t.n2_;
      const int64_t base2[3] = {l1.Coord(xyz, 0) << n2, l1.Coord(xyz, 1) << n2,
                                l1.Coord(xyz, 2) << n2};
      Real tt = cx.t_start;
      int entry = -1;
      if (xyz != prev) {
        for (int a = 0; a < 3; ++a) {
          if (cx.D[a] == Real(0)) continue;
          Real face = Real(base2[a]) + (cx.s[a] > 0 ? Real(0) : cx.s1);
          Real ta = (face - cx.o[a]) / cx.D[a];
          if (entry < 0 || ta > tt) {
            tt = ta;
            entry = a;
          }
        }
      }
      const int64_t size2 = int64_t(1) << n2;
      int64_t w[3];
      for (int a = 0; a < 3; ++a) {
        Real pa = (entry < 0 ? cx.p[a] : cx.o[a] + tt * cx.D[a]) - Real(base2[a]);
        w[a] = a == entry ? (cx.s[a] > 0 ? 0 : size2 - 1)
                          : internal::StartVoxel(pa, cx.s[a], size2);
      }
      *xyz2 = l2.Pack(w);
      return MakeDda(cx, l2, w, base2, Real(1));
    }

    void AddMoves(const Dda& dda, TraceCounters* c) const {
      for (int a = 0; a < 3; ++a) c->moves[a] += dda.moves[a];
    }
  };

  // A step's state from its start voxel v; `base` is the step grid's corner
  // and `size` its voxel size, in finest voxels.
  static Dda MakeDda(const Ctx& cx, const internal::StepLayout& lay, const int64_t v[3],
                     const int64_t base[3], Real size) {
    Dda dda;
    for (int a = 0; a < 3; ++a) {
      dda.inc[a] = lay.Inc(a, cx.s[a]);
      if (cx.D[a] == Real(0)) {
        dda.tmax[a] = std::numeric_limits<Real>::infinity();
        dda.tdelta[a] = std::numeric_limits<Real>::infinity();
        continue;
      }
      Real next = Real(base[a]) + (Real(v[a]) + (cx.s[a] > 0 ? Real(1) : Real(0))) * size;
      dda.tmax[a] = (next - cx.o[a]) / cx.D[a];
      dda.tdelta[a] = size / std::fabs(cx.D[a]);
    }
    return dda;
  }

  OctreeView tree_;
  int n1_ = 0, n2_ = 0;
};

}  // namespace vox

#endif  // VOX_TESTS_STUDY_AW_TRACER_H_

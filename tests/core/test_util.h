// Helpers shared by the core tracer tests: ray counts, random rays with fixed
// seeds, voxel sets, and running a tracer against the exact Reference.
// Not thread-safe (Rng holds state); use one per test.
#ifndef VOX_TESTS_CORE_TEST_UTIL_H_
#define VOX_TESTS_CORE_TEST_UTIL_H_

#include <algorithm>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/octree.h"
#include "core/ray.h"
#include "core/tracer.h"
#include "tests/study/reference.h"

namespace vox::testing {

// Rays per property configuration: the VOX_CORE_RAYS environment variable
// when set (the "long" CTest registrations set it to 100000), else
// `default_count`.
int RayCount(int default_count);
bool LongRun();

std::vector<Voxel> ToVoxels(const std::vector<LeafPoint>& points);
std::vector<LeafPoint> ToLeafPoints(const std::vector<Voxel>& voxels);

class Rng {
 public:
  explicit Rng(uint64_t seed) : gen_(seed) {}
  uint64_t Bits() { return gen_(); }
  // Uniform in [lo, hi), with all 53 bits random.
  double Uniform(double lo, double hi);
  int64_t Int(int64_t lo, int64_t hi);  // [lo, hi]
  bool Chance(double p) { return Uniform(0, 1) < p; }
  // A random direction (Gaussian), scaled by a random power of two in
  // [2^-30, 2^30]; sometimes with a zero or -0.0 component.
  glm::dvec3 Direction(bool allow_zero_components = true);
  // A point uniformly inside voxel v, sometimes on its faces.
  glm::dvec3 PointIn(const Voxel& v);
  std::mt19937_64& gen() { return gen_; }

 private:
  std::mt19937_64 gen_;
};

// `count` distinct random voxels inside the box [lo, lo + extent)^3.
std::vector<Voxel> RandomVoxels(Rng& rng, size_t count, const Voxel& lo, int64_t extent);
// Every voxel of [lo, lo + extent)^3 with probability `density`.
std::vector<Voxel> DenseVoxels(Rng& rng, double density, const Voxel& lo, int64_t extent);
// A generated shape (core/shapes.h), shifted by `offset`.
std::vector<Voxel> ShapeVoxels(const std::string& spec, const Voxel& offset, int* levels);

// A ray from outside the grid [0, 2^levels)^3 towards `target`, its origin at
// `distance` (in voxels) from the grid's centre.
Ray RayFromOutside(Rng& rng, int levels, const glm::dvec3& target, double distance);
// A ray from `origin` in a random direction.
Ray RayFrom(Rng& rng, const glm::dvec3& origin);

// A tree built from voxels with one brick level, and tracers over it.
template <class TracerT>
struct TracerUnderTest {
  std::string name;  // "bl=3 n1=2"
  std::shared_ptr<MemoryOctree> tree;
  TracerT tracer;
};

// The tracer vox-render traces with: render/renderer.h's RenderTracer and
// render/lod.h's LodLevelTracer are this type (tests/render/beam_test.cpp
// checks it), 64-bit words up to kFixed64MaxLevels and 128-bit above, with a
// double per-ray set-up; the renderer gives it the store's occupied box.
// vox-probe and vox.probe answer with it by default (--tracer render).
using RenderTracerUnderTest = AutoTracer<double>;

// How far (in voxels) the double set-up of RenderTracerUnderTest may move a
// ray, from IEEE double alone: the set-up (clipping to the grid, the entry
// point, the first h and l, the transition's entry point) evaluates each
// coordinate in at most 8 rounded operations on values no larger than
// |origin|_inf + 2^levels, each rounding off by at most 2^-53 of its value:
// 8 * 2^-53 * (|origin|_inf + 2^levels). A first hit the exact reference
// refuses but a ray moved by at most this explains (WithinEpsilon) is a
// precision difference; any other is a logic failure.
double DoubleSetupBound(const Ray& ray, int levels);

// One tracer per (brick level, n1) pair. Fails when the tree cannot be built
// or a split is refused. `occupied_box`: give each tracer the voxels'
// bounding box (SetOccupiedBox), as the renderer does.
template <class TracerT = DefaultTracer>
StatusOr<std::vector<TracerUnderTest<TracerT>>> MakeTracers(const std::vector<Voxel>& voxels,
                                                             int levels,
                                                             const std::vector<int>& brick_levels,
                                                             const std::vector<int>& n1s,
                                                             bool occupied_box = false) {
  std::vector<TracerUnderTest<TracerT>> out;
  const std::vector<LeafPoint> points = ToLeafPoints(voxels);
  int64_t lo[3] = {INT64_MAX, INT64_MAX, INT64_MAX}, hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
  for (const Voxel& v : voxels)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min<int64_t>(lo[a], v[a]);
      hi[a] = std::max<int64_t>(hi[a], v[a]);
    }
  for (int bl : brick_levels) {
    auto built = MemoryOctree::Build(points, levels, bl);
    if (!built.ok()) return built.status();
    std::shared_ptr<MemoryOctree> tree = std::move(built).value();
    for (int n1 : n1s) {
      auto tr = TracerT::Create(tree->view(), n1);
      if (!tr.ok()) return tr.status();
      if (occupied_box && !voxels.empty()) tr->SetOccupiedBox(lo, hi);
      out.push_back({"bl=" + std::to_string(bl) + " n1=" + std::to_string(n1), tree, *tr});
    }
  }
  return out;
}

// Traces `ray` with `tracer` and checks it against `expected`; returns "" or
// the failure.
template <class TracerT>
std::string TraceAndCheck(const TracerT& tracer, const Reference& ref, const ExactRay& ray,
                          const RefHit& expected, TraceCounters* counters = nullptr) {
  auto got = tracer.FirstHit(ray.ray(), counters);
  if (!got.ok()) return "tracer error " + got.status().ToString() + " [" + RayString(ray.ray()) + "]";
  return CheckFirstHit(ref, ray, expected, *got);
}

}  // namespace vox::testing

#endif  // VOX_TESTS_CORE_TEST_UTIL_H_

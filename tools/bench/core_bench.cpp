// Google Benchmark program for vox's core traversal: driving-axis moves,
// passive moves, empty-space skips, whole first-hit queries, and single step
// against two steps. Rates are DDA moves (or rays) per second on one thread.
//
//   build/tools/bench/vox-core-bench --benchmark_repetitions=5
//     --benchmark_report_aggregates_only=true   (one line)
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "core/core.h"
#include "core/shapes.h"

namespace vox {
namespace {

std::unique_ptr<MemoryOctree> MakeTree(const char* shape, int brick_levels) {
  auto vol = GenerateShape(shape);
  if (!vol.ok()) std::abort();
  auto t = MemoryOctree::Build(std::move(vol->voxels), vol->levels,
                               std::max(1, vol->levels - brick_levels));
  if (!t.ok()) std::abort();
  return std::move(t).value();
}

// Rays through an empty 2^20 grid: every move is a DDA move inside the skip
// loop. `slope` sets how many moves are passive: 0 gives driving moves only.
template <class Fixed>
void BM_Moves(benchmark::State& state) {
  const double slope = double(state.range(0)) / 100.0;
  auto tree = MemoryOctree::Build({}, 20, 20).value();
  auto tracer = Tracer<Fixed, long double>::Create(tree->view(), 20).value();
  Ray ray{{0.0, 1000.5, 2000.25}, {1.0, slope, slope * 0.5}};
  TraceCounters c;
  for (auto _ : state) {
    auto h = tracer.FirstHit(ray, &c);
    benchmark::DoNotOptimize(h);
  }
  state.counters["moves/s"] =
      benchmark::Counter(double(c.total_moves()), benchmark::Counter::kIsRate);
  state.counters["passive_frac"] = double(c.passive_moves) / double(c.total_moves());
  state.SetItemsProcessed(int64_t(c.total_moves()));
}
BENCHMARK(BM_Moves<Fixed64>)->Name("DrivingMoves/fixed64")->Arg(0);
BENCHMARK(BM_Moves<Fixed128>)->Name("DrivingMoves/fixed128")->Arg(0);
BENCHMARK(BM_Moves<Fixed64>)->Name("PassiveMix/fixed64")->Arg(70);
BENCHMARK(BM_Moves<Fixed128>)->Name("PassiveMix/fixed128")->Arg(70);

// Random rays from outside aimed at the volume's centre region.
std::vector<Ray> AimedRays(int levels, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double n = std::ldexp(1.0, levels);
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    double th = 2 * M_PI * u(rng), z = 2 * u(rng) - 1, r = std::sqrt(1 - z * z);
    glm::dvec3 from =
        glm::dvec3(n / 2) + 1.5 * n * glm::dvec3(r * std::cos(th), r * std::sin(th), z);
    glm::dvec3 to =
        glm::dvec3(n * (0.3 + 0.4 * u(rng)), n * (0.3 + 0.4 * u(rng)), n * (0.3 + 0.4 * u(rng)));
    rays.push_back({from, to - from});
  }
  return rays;
}

// Whole first-hit queries on a sphere shell; range(0) is n1 (== levels: single step).
void BM_FirstHit(benchmark::State& state, const char* shape) {
  static std::unique_ptr<MemoryOctree> tree;
  static std::string built;
  if (built != shape) {
    tree = MakeTree(shape, 5);
    built = shape;
  }
  auto tracer = DefaultTracer::Create(tree->view(), int(state.range(0))).value();
  auto rays = AimedRays(tree->levels(), 4096, 42);
  TraceCounters c;
  size_t i = 0;
  for (auto _ : state) {
    auto h = tracer.FirstHit(rays[i++ % rays.size()], &c);
    benchmark::DoNotOptimize(h);
  }
  state.counters["rays/s"] = benchmark::Counter(double(c.rays), benchmark::Counter::kIsRate);
  state.counters["moves/ray"] = double(c.total_moves()) / double(c.rays);
  state.counters["skips/ray"] = double(c.skips) / double(c.rays);
  state.counters["hit_rate"] = double(c.hits) / double(c.rays);
}
BENCHMARK_CAPTURE(BM_FirstHit, sphere1024, "sphere:1024")->Arg(10)->Arg(4)->Arg(5)->Arg(6)->Arg(7);

// Empty-space skipping: sparse random voxels; skips and moves per ray.
BENCHMARK_CAPTURE(BM_FirstHit, noise1024, "noise:1024")->Arg(10)->Arg(6);

// The per-ray floor: a close view's rays, each a whole first-hit query that
// ends a few voxels past the occupied box's face (a one-voxel wall across a
// 2^10 grid, seen from 400 voxels by a 60-degree pinhole, 256 x 256 rays, the
// renderer's tracer and its occupied box). What a ray costs from its
// direction to its first DDA state, the jumps, both steps' descents, one
// transition and the hit: ns per ray on one thread (the time per iteration
// divided by 65,536).
void BM_CloseRays(benchmark::State& state) {
  constexpr int kLevels = 10, kWall = 512, kSide = 256;
  static std::unique_ptr<MemoryOctree> tree = [] {
    std::vector<LeafPoint> wall;
    for (uint64_t y = 0; y < (1u << kLevels); ++y)
      for (uint64_t x = 0; x < (1u << kLevels); ++x) wall.push_back({x, y, kWall, 1});
    std::sort(wall.begin(), wall.end(), MortonLess);
    return MemoryOctree::Build(std::move(wall), kLevels, 6).value();
  }();
  auto tracer = Tracer<Fixed64, double>::Create(tree->view(), 6).value();
  const int64_t lo[3] = {0, 0, kWall}, hi[3] = {(1 << kLevels) - 1, (1 << kLevels) - 1, kWall};
  tracer.SetOccupiedBox(lo, hi);
  std::vector<Ray> rays;
  const double half = std::tan(M_PI / 6);
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x)
      rays.push_back(
          {{512.3, 511.7, kWall + 400.0},
           {(2 * (x + 0.5) / kSide - 1) * half, (1 - 2 * (y + 0.5) / kSide) * half, -1.0}});
  TraceCounters c;
  for (auto _ : state)
    for (const Ray& r : rays) {
      auto h = tracer.FirstHit(r, &c);
      benchmark::DoNotOptimize(h);
    }
  state.counters["ns/ray"] =
      benchmark::Counter(double(rays.size()) * double(state.iterations()),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["hit_rate"] = double(c.hits) / double(c.rays);
  state.counters["moves/ray"] = double(c.total_moves()) / double(c.rays);
  state.counters["cells/ray"] = double(c.cells_visited) / double(c.rays);
}
BENCHMARK(BM_CloseRays)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace vox

BENCHMARK_MAIN();

// Google Benchmark program for vox's core traversal: driving-axis moves,
// passive moves, empty-space skips, whole first-hit queries, and single step
// against two steps. Rates are DDA moves (or rays) per second on one thread.
//
//   build/tools/bench/vox-core-bench --benchmark_repetitions=5
//     --benchmark_report_aggregates_only=true   (one line)
#include <benchmark/benchmark.h>

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

}  // namespace
}  // namespace vox

BENCHMARK_MAIN();

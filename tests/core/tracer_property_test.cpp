// Property tests of the tracer against the exact Reference: random rays with
// fixed seeds, from outside and inside, on grids 2^6 to 2^40, sparse and
// dense, at several brick levels and splits (single step where the grid has
// at most 20 levels; two steps with n1 below, at and above the brick level,
// so second steps fetch bricks and first steps walk through them).
//
// Rays per configuration: VOX_CORE_RAYS (10^5 in the "long" registration),
// else a small default. A failure prints the ray in C99 hex floats.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <functional>

#include "tests/study/reference.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

struct Config {
  std::string name;
  int levels = 0;
  std::vector<Voxel> voxels;
  std::vector<int> brick_levels, n1s;
  int default_rays = 1000;
  uint64_t seed = 1;
  // Every `traverse_every`-th ray also checks Traverse (0: never).
  int traverse_every = 0;
  std::function<Ray(Rng&, const Config&)> make_ray;
};

// A mix: towards an occupied voxel from outside, towards any point from
// outside, from inside near an occupied voxel (sometimes inside it), and
// from a random point inside the grid.
Ray MixedRay(Rng& rng, const Config& cfg) {
  const double n = std::ldexp(1.0, cfg.levels);
  const Voxel& v = cfg.voxels[size_t(rng.Int(0, int64_t(cfg.voxels.size()) - 1))];
  const double kind = rng.Uniform(0, 1);
  if (kind < 0.4) {
    glm::dvec3 target = rng.PointIn(v);
    return RayFromOutside(rng, cfg.levels, target, n * rng.Uniform(0.9, 3));
  }
  if (kind < 0.55) {
    glm::dvec3 target(rng.Uniform(0, n), rng.Uniform(0, n), rng.Uniform(0, n));
    return RayFromOutside(rng, cfg.levels, target, n * rng.Uniform(0.9, 3));
  }
  if (kind < 0.85) {
    glm::dvec3 o = rng.PointIn(v);
    if (rng.Chance(0.7)) {
      double r = std::ldexp(1.0, int(rng.Int(0, std::min(cfg.levels, 6))));
      o += glm::dvec3(rng.Uniform(-r, r), rng.Uniform(-r, r), rng.Uniform(-r, r));
    }
    return RayFrom(rng, o);
  }
  return RayFrom(rng, glm::dvec3(rng.Uniform(0, n), rng.Uniform(0, n), rng.Uniform(0, n)));
}

// For huge grids: origins near an occupied voxel (within 2^8), aimed at
// another occupied voxel nearby, so rays stay short; one in 50 from far
// outside towards an occupied voxel.
Ray NearRay(Rng& rng, const Config& cfg) {
  const Voxel& v = cfg.voxels[size_t(rng.Int(0, int64_t(cfg.voxels.size()) - 1))];
  glm::dvec3 target = rng.PointIn(v);
  if (rng.Chance(0.02))
    return RayFromOutside(rng, cfg.levels, target, std::ldexp(1.0, cfg.levels) * rng.Uniform(0.9, 2));
  glm::dvec3 o = target;
  double r = std::ldexp(1.0, int(rng.Int(0, 8)));
  o += glm::dvec3(rng.Uniform(-r, r), rng.Uniform(-r, r), rng.Uniform(-r, r));
  Ray ray;
  ray.origin = o;
  ray.dir = rng.Chance(0.8) ? (target - o) * std::ldexp(1.0, int(rng.Int(-10, 10)))
                            : rng.Direction();
  if (ray.dir.x == 0 && ray.dir.y == 0 && ray.dir.z == 0) ray.dir = rng.Direction();
  return ray;
}

template <class TracerT>
struct Result {
  uint64_t rays = 0, hits = 0, ambiguous = 0;
  std::vector<uint64_t> near, far;  // failures within / beyond the budget's eps
  double seconds = 0;
};

// How wrong a tracer may be. A failure is a precision failure when it is
// explained by a ray within `eps` voxels of a lattice edge or face
// (WithinEpsilon); others are logic failures and fail the test. Precision
// failures may reach `max_rate` of the rays.
struct Budget {
  double eps = 1e-6;
  double max_rate = 1e-4;
  // The render tracer: eps per ray is DoubleSetupBound (test_util.h), and
  // its tracers get the occupied box as the renderer gives it.
  bool render = false;
};

// The render's tracer (RenderTracerUnderTest): wrong answers only within the
// bound IEEE double puts on its set-up, at most `max_rate` of the rays. Every
// configuration requires 0: the render's tracer meets the exact reference on
// every ray, as the README says.
constexpr Budget RenderBudget(double max_rate) { return Budget{0, max_rate, true}; }

// Fixed64's drift on a 2^30 grid: l += q gains at most 2^-40 step units a
// move; over up to 2^20 moves of a 20-level step that is 2^-20 step units,
// 2^-10 voxel when the other step has 10 levels (and alike for 10+20).
constexpr Budget kFixed64Drift30{0x1p-9, 1e-3};
// On a 2^40 grid split 20+20 the same drift reaches 2^20 moves * 2^-40 step
// units = 2^-20 first-step units = 1 second-step voxel: every wrong first
// hit must be within a voxel of an accepted one. The bound says nothing of
// how many rays come that close to a boundary, so no rate is asserted
// (max_rate 1): the 64-bit word is not exact on 2^40 grids, which is why
// AutoTracer does not use it there.
constexpr Budget kFixed64Drift40{1, 1};

// The perturbations tried when classifying a failure, to print how far off
// the tracer was (data for the accuracy study).
constexpr double kLadder[] = {1e-9, 1e-6, 1e-3, 1e-1, 0.5, 1, 2, 4, 8};
constexpr int kRungs = int(sizeof(kLadder) / sizeof(kLadder[0]));

// Runs `cfg` with tracers of type TracerT, prints the failure counts per
// tracer and checks them against `budget`.
template <class TracerT = DefaultTracer>
Result<TracerT> RunConfig(const Config& cfg, Budget budget = {}, const char* label = "Fixed64") {
  Result<TracerT> res;
  auto t0 = std::chrono::steady_clock::now();
  Reference ref(cfg.voxels, cfg.levels);
  auto tracers = MakeTracers<TracerT>(cfg.voxels, cfg.levels, cfg.brick_levels, cfg.n1s,
                                      /*occupied_box=*/budget.render);
  EXPECT_TRUE(tracers.ok()) << tracers.status().ToString();
  if (!tracers.ok()) return res;
  res.near.assign(tracers->size(), 0);
  res.far.assign(tracers->size(), 0);
  std::vector<std::vector<uint64_t>> ladder(tracers->size(), std::vector<uint64_t>(kRungs + 1));
  Rng rng(cfg.seed);
  const int rays = RayCount(cfg.default_rays);
  int printed = 0, printed_near = 0;
  for (int i = 0; i < rays; ++i) {
    const Ray ray = cfg.make_ray(rng, cfg);
    const ExactRay er(ray);
    const RefHit expected = ref.FirstHit(er);
    ++res.rays;
    res.hits += expected.hit;
    res.ambiguous += expected.ambiguous;
    const bool traverse = cfg.traverse_every > 0 && i % cfg.traverse_every == 0;
    for (size_t k = 0; k < tracers->size(); ++k) {
      const auto& t = (*tracers)[k];
      auto got = t.tracer.FirstHit(ray);
      if (!got.ok()) {
        ++res.far[k];
        ADD_FAILURE() << cfg.name << " [" << t.name << "] ray " << i << ": "
                      << got.status().ToString() << " [" << RayString(ray) << "]";
        continue;
      }
      std::string msg = CheckFirstHit(ref, er, expected, *got);
      if (!msg.empty()) {
        int rung = 0;
        while (rung < kRungs && !WithinEpsilon(ref, er, expected, *got, kLadder[rung])) ++rung;
        ++ladder[k][rung];
        const double eps = budget.render ? DoubleSetupBound(ray, cfg.levels) : budget.eps;
        if (budget.render ? WithinEpsilon(ref, er, expected, *got, eps)
                          : rung < kRungs && kLadder[rung] <= eps) {
          ++res.near[k];
          if (printed_near++ < 3)
            std::printf("  precision failure (within %g voxel): %s [%s] ray %d: %s\n",
                        budget.render ? eps : kLadder[rung], cfg.name.c_str(), t.name.c_str(), i,
                        msg.c_str());
          continue;
        }
      }
      if (msg.empty() && traverse) {
        std::vector<Hit> visits;
        Status s = t.tracer.Traverse(ray, [&](const Hit& h) {
          visits.push_back(h);
          return true;
        });
        msg = s.ok() ? CheckTraversal(ref, er, visits) : "Traverse: " + s.ToString();
        if (!msg.empty()) msg = "Traverse " + msg;
      }
      if (msg.empty()) continue;
      ++res.far[k];
      if (printed < 8) {
        ++printed;
        ADD_FAILURE() << cfg.name << " [" << t.name << "] ray " << i << ": " << msg;
      }
    }
  }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%s (%s): %zu voxels, %llu rays (%llu hit, %llu ambiguous), %.1f s\n",
              cfg.name.c_str(), label, ref.size(), (unsigned long long)res.rays,
              (unsigned long long)res.hits, (unsigned long long)res.ambiguous, res.seconds);
  for (size_t k = 0; k < tracers->size(); ++k) {
    std::printf("  %-12s failures: %llu logic, %llu precision (eps %s)",
                (*tracers)[k].name.c_str(), (unsigned long long)res.far[k],
                (unsigned long long)res.near[k],
                budget.render ? "double set-up bound" : std::to_string(budget.eps).c_str());
    if (res.far[k] + res.near[k] > 0) {
      std::printf("; wrong answers explained within eps:");
      for (int r = 0; r < kRungs; ++r)
        if (ladder[k][r]) std::printf(" %g: %llu", kLadder[r], (unsigned long long)ladder[k][r]);
      if (ladder[k][kRungs]) std::printf(" beyond: %llu", (unsigned long long)ladder[k][kRungs]);
    }
    std::printf("\n");
    EXPECT_EQ(res.far[k], 0u) << cfg.name << " [" << (*tracers)[k].name << "]";
    EXPECT_LE(double(res.near[k]), budget.max_rate * double(res.rays))
        << cfg.name << " [" << (*tracers)[k].name << "]: precision failures";
  }
  std::fflush(stdout);
  return res;
}

Config Make(std::string name, int levels, std::vector<Voxel> voxels, std::vector<int> bls,
            std::vector<int> n1s, int default_rays, uint64_t seed) {
  Config c;
  c.name = std::move(name);
  c.levels = levels;
  c.voxels = std::move(voxels);
  c.brick_levels = std::move(bls);
  c.n1s = std::move(n1s);
  c.default_rays = default_rays;
  c.seed = seed;
  c.make_ray = MixedRay;
  return c;
}

// ---------------------------------------------------------------- 2^6

TEST(TracerProperty, Grid64DenseRandom) {
  Rng rng(11);
  Config c = Make("2^6 dense 30%", 6, DenseVoxels(rng, 0.3, {0, 0, 0}, 64), {6, 3}, {6, 5, 3, 1},
                  4000, 101);
  c.traverse_every = 10;
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid64SparseRandom) {
  Rng rng(12);
  Config c = Make("2^6 sparse 0.3%", 6, DenseVoxels(rng, 0.003, {0, 0, 0}, 64), {6, 2},
                  {6, 4, 2, 1}, 4000, 102);
  c.traverse_every = 5;
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid64Sphere) {
  int levels = 0;
  Config c = Make("sphere:64", 6, ShapeVoxels("sphere:64", {0, 0, 0}, &levels), {6, 4},
                  {6, 3, 2, 5}, 4000, 103);
  ASSERT_EQ(levels, 6);
  c.traverse_every = 10;
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

// ---------------------------------------------------------------- 2^8 .. 2^10

TEST(TracerProperty, Grid256Cubes) {
  int levels = 0;
  Config c = Make("cubes:256", 8, ShapeVoxels("cubes:256", {0, 0, 0}, &levels), {8, 4},
                  {8, 4, 2, 6}, 3000, 104);
  ASSERT_EQ(levels, 8);
  c.traverse_every = 20;
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid256Torus) {
  int levels = 0;
  Config c = Make("torus:256", 8, ShapeVoxels("torus:256", {0, 0, 0}, &levels), {8, 3},
                  {8, 5, 3}, 3000, 105);
  ASSERT_EQ(levels, 8);
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid1024Noise) {
  int levels = 0;
  Config c = Make("noise:1024", 10, ShapeVoxels("noise:1024", {0, 0, 0}, &levels), {10, 5},
                  {10, 5, 3, 7}, 1500, 106);
  ASSERT_EQ(levels, 10);
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

// ---------------------------------------------------------------- 2^16, 2^20

// Dense blobs and a sparse scatter, placed across octant boundaries.
std::vector<Voxel> Blobs(Rng& rng, int levels, int blobs, int64_t extent, double density,
                         size_t scatter) {
  const int64_t n = int64_t(1) << levels;
  std::vector<Voxel> out;
  for (int b = 0; b < blobs; ++b) {
    Voxel lo;
    for (int a = 0; a < 3; ++a) {
      // Half the blobs straddle a power-of-two boundary.
      if (b % 2 == 0) {
        const int k = int(rng.Int(1, std::min(levels, 12)));
        const int64_t boundary = (n >> k) * (2 * rng.Int(0, (int64_t(1) << (k - 1)) - 1) + 1);
        lo[a] = std::clamp<int64_t>(boundary - extent / 2, 0, n - extent);
      } else {
        lo[a] = rng.Int(0, n - extent);
      }
    }
    std::vector<Voxel> blob = DenseVoxels(rng, density, lo, extent);
    out.insert(out.end(), blob.begin(), blob.end());
  }
  std::vector<Voxel> sc = RandomVoxels(rng, scatter, {0, 0, 0}, n);
  out.insert(out.end(), sc.begin(), sc.end());
  return out;
}

TEST(TracerProperty, Grid2p16Blobs) {
  Rng rng(16);
  Config c = Make("2^16 blobs", 16, Blobs(rng, 16, 12, 16, 0.4, 3000), {16, 9},
                  {16, 9, 5, 12}, 1000, 116);
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid2p20Blobs) {
  Rng rng(20);
  Config c = Make("2^20 blobs", 20, Blobs(rng, 20, 12, 16, 0.4, 3000), {20, 11},
                  {20, 11, 6, 14}, 600, 120);
  c.make_ray = NearRay;
  RunConfig(c);
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

// ---------------------------------------------------------------- 2^30, 2^40

TEST(TracerProperty, Grid2p30Blobs) {
  Rng rng(30);
  Config c = Make("2^30 blobs", 30, Blobs(rng, 30, 10, 16, 0.4, 200), {12, 25},
                  {10, 15, 20}, 600, 130);
  c.make_ray = NearRay;
  RunConfig<DefaultTracer>(c, kFixed64Drift30, "Fixed64");
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerProperty, Grid2p40Blobs) {
  Rng rng(40);
  Config c = Make("2^40 blobs", 40, Blobs(rng, 40, 10, 16, 0.4, 100), {12, 30}, {20}, 600, 140);
  c.make_ray = NearRay;
  // 2% of NearRay's rays come from far outside: over a 20-level first step
  // Fixed64 drifts by up to one voxel (kFixed64Drift40). Measured with 10^5
  // rays: 49 wrong first hits (0.05%), all within 0.5 voxel. No rate is
  // asserted for the 64-bit word here: no tracer vox uses takes it above
  // 2^26 (AutoTracer); Fixed128 and the render's tracer must be exact.
  RunConfig<DefaultTracer>(c, kFixed64Drift40, "Fixed64");
  RunConfig<Tracer<Fixed128, long double>>(c, Budget{}, "Fixed128");
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

// ---------------------------------------------------------------- precision

// Rays from outside the grid (1 to 2 grid sizes from its centre) towards
// occupied voxels: on 2^30 and 2^40 grids their first step crosses up to
// ~2^20 first-step voxels, so the error of l += q accumulates.
Ray FarRay(Rng& rng, const Config& cfg) {
  const Voxel& v = cfg.voxels[size_t(rng.Int(0, int64_t(cfg.voxels.size()) - 1))];
  return RayFromOutside(rng, cfg.levels, rng.PointIn(v),
                        std::ldexp(1.0, cfg.levels) * rng.Uniform(1, 2));
}

using Tracer128 = Tracer<Fixed128, long double>;

TEST(TracerPrecision, Grid2p40FromFarOutside) {
  Rng rng(41);
  Config c = Make("2^40 far rays", 40, Blobs(rng, 40, 10, 16, 0.4, 100), {12}, {20}, 400, 141);
  c.make_ray = FarRay;
  // Fixed64 (39 fractional bits) is not exact here: measured 18 of these 400
  // rays (4.5%; 3.1% of 1000 in an earlier run) with a wrong first hit, all
  // within 0.5 voxel. The test asserts only what the drift bound
  // (kFixed64Drift40) gives, that each is within a voxel of an accepted
  // answer; AutoTracer, vox's default and the render's, takes 128-bit words
  // above 2^26, and those must be exact.
  RunConfig<DefaultTracer>(c, kFixed64Drift40, "Fixed64");
  RunConfig<Tracer128>(c, Budget{}, "Fixed128");
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

TEST(TracerPrecision, Grid2p30FromFarOutside) {
  Rng rng(31);
  Config c = Make("2^30 far rays", 30, Blobs(rng, 30, 10, 16, 0.4, 100), {15}, {10, 20}, 200, 131);
  c.make_ray = FarRay;
  // Measured with 10^5 rays: 5 (10+20) and 2 (20+10) wrong first hits, all
  // within 0.001 voxel.
  RunConfig<DefaultTracer>(c, kFixed64Drift30, "Fixed64");
  RunConfig<Tracer128>(c, Budget{}, "Fixed128");
  RunConfig<RenderTracerUnderTest>(c, RenderBudget(0), "render");
}

}  // namespace
}  // namespace vox::testing

// Rays from far origins (10^6 .. 10^300 voxels away) against the exact
// Reference (tests/study/reference.h): axis-parallel rays, diagonals and rays
// whose direction components are tiny ratios that bring them back onto the
// grid, on a dense 2^6 grid and a sparse 2^20 one; origins beyond the
// documented range (core/ray.h, kMaxOriginMagnitude) are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tests/core/test_util.h"
#include "tests/study/reference.h"

namespace vox::testing {
namespace {

const double kDistances[] = {1e6, 1e9, 1e17, 1e20, 1e25, 1e30, 1e100, 1e200, 1e300};

struct Case {
  std::vector<Voxel> voxels;
  int levels;
  Reference ref;
  std::vector<TracerUnderTest<DefaultTracer>> tracers;
  // The render's tracer (test_util.h), with the occupied box: held to the
  // same exactness.
  std::vector<TracerUnderTest<RenderTracerUnderTest>> render;
  Case(std::vector<Voxel> v, int l, const std::vector<int>& bls, const std::vector<int>& n1s)
      : voxels(std::move(v)), levels(l), ref(voxels, levels) {
    auto t = MakeTracers(voxels, levels, bls, n1s);
    EXPECT_TRUE(t.ok()) << t.status().ToString();
    if (t.ok()) tracers = std::move(t).value();
    auto r = MakeTracers<RenderTracerUnderTest>(voxels, levels, bls, n1s, /*occupied_box=*/true);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (r.ok()) render = std::move(r).value();
  }
  // Returns the number of rays the reference says hit.
  int CheckAll(const std::vector<Ray>& rays, const std::string& what) const {
    int hits = 0, failures = 0;
    for (const Ray& ray : rays) {
      const ExactRay er(ray);
      const RefHit expected = ref.FirstHit(er);
      hits += expected.hit;
      for (const auto& t : tracers) {
        const std::string msg = TraceAndCheck(t.tracer, ref, er, expected);
        if (!msg.empty() && ++failures <= 10)
          ADD_FAILURE() << what << " [" << t.name << "]: " << msg;
      }
      for (const auto& t : render) {
        const std::string msg = TraceAndCheck(t.tracer, ref, er, expected);
        if (!msg.empty() && ++failures <= 10)
          ADD_FAILURE() << what << " [render " << t.name << "]: " << msg;
      }
    }
    return hits;
  }
};

// Axis-parallel rays from `dist` away along each of the six directions,
// through the centres of voxels of the occupied region [lo, lo + n)^3.
std::vector<Ray> AxisRays(Rng& rng, double dist, int64_t lo, int64_t n, int count) {
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    const int axis = int(rng.Int(0, 2));
    const double sign = rng.Chance(0.5) ? 1.0 : -1.0;
    Ray r;
    for (int a = 0; a < 3; ++a) r.origin[a] = double(lo + rng.Int(0, n - 1)) + 0.5;
    r.origin[axis] = -sign * dist;
    r.dir = glm::dvec3(0.0);
    r.dir[axis] = sign;
    rays.push_back(r);
  }
  return rays;
}

// Origin `dist` away on one axis, the other two direction components tiny
// ratios r / dist that bring the ray back within the occupied region: the
// entry point depends on the low bits of those ratios, which only exact
// clipping gets right.
std::vector<Ray> TiltedRays(Rng& rng, double dist, int64_t lo, int64_t n, int count) {
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    const int axis = int(rng.Int(0, 2));
    const double sign = rng.Chance(0.5) ? 1.0 : -1.0;
    Ray r;
    for (int a = 0; a < 3; ++a) {
      const double start = double(lo) + rng.Uniform(0, double(n));
      const double end = double(lo) + rng.Uniform(0, double(n));
      r.origin[a] = start;
      r.dir[a] = (end - start) / dist;
    }
    r.origin[axis] = -sign * dist;
    r.dir[axis] = sign * (1.0 + rng.Uniform(0, 0.5));
    rays.push_back(r);
  }
  return rays;
}

// Diagonal rays (+-1, +-1, 0) from (X, X, z): both big coordinates round
// alike, so the ray runs exactly along a diagonal of the grid.
std::vector<Ray> DiagonalRays(Rng& rng, double dist, int64_t lo, int64_t n, int count) {
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    Ray r;
    const double sx = rng.Chance(0.5) ? 1.0 : -1.0, sy = rng.Chance(0.5) ? 1.0 : -1.0;
    r.origin = glm::dvec3(-sx * dist, -sy * dist, double(lo + rng.Int(0, n - 1)) + 0.5);
    r.dir = glm::dvec3(sx, sy, 0.0);
    rays.push_back(r);
  }
  return rays;
}

TEST(FarOrigins, MatchTheExactReferenceUpTo1e300) {
  Rng rng(2026);
  Case dense(DenseVoxels(rng, 0.2, {0, 0, 0}, 64), 6, {6, 3}, {6, 5, 3, 1});
  const int64_t n20 = int64_t(1) << 20;
  Case sparse(DenseVoxels(rng, 0.3, {n20 / 2 - 8, n20 / 2 - 8, n20 / 2 - 8}, 16), 20, {20, 10},
              {20, 10, 17});
  for (double dist : kDistances) {
    char what[64];
    snprintf(what, sizeof what, "origins %g away", dist);
    int hits = dense.CheckAll(AxisRays(rng, dist, 0, 64, 150), std::string(what) + ", axis, 2^6");
    EXPECT_GT(hits, 100) << what;  // density 0.2 over 64 voxels: almost every row is hit
    hits = dense.CheckAll(TiltedRays(rng, dist, 0, 64, 150), std::string(what) + ", tilted, 2^6");
    EXPECT_GT(hits, 100) << what;
    dense.CheckAll(DiagonalRays(rng, dist, 0, 64, 40), std::string(what) + ", diagonal, 2^6");
    hits = sparse.CheckAll(AxisRays(rng, dist, n20 / 2 - 8, 16, 60),
                           std::string(what) + ", axis, 2^20");
    EXPECT_GT(hits, 30) << what;
    hits = sparse.CheckAll(TiltedRays(rng, dist, n20 / 2 - 8, 16, 60),
                           std::string(what) + ", tilted, 2^20");
    EXPECT_GT(hits, 20) << what;
  }
}

TEST(FarOrigins, TheProbeRayOfTheReport) {
  // `X 100.5 100.5 -1 0 0` on a grid with voxel (14, 100, 100) occupied.
  std::vector<Voxel> voxels = {{14, 100, 100}, {3, 100, 100}, {14, 101, 100}};
  Case c(voxels, 8, {8, 4}, {8, 4});
  for (double x : {1e6, 1e20, 1e25, 1e30, 1e100, 1e300}) {
    for (const auto& t : c.tracers) {
      auto hit = t.tracer.FirstHit(Ray{{x, 100.5, 100.5}, {-1, 0, 0}});
      ASSERT_TRUE(hit.ok()) << hit.status().ToString();
      ASSERT_TRUE(hit->has_value()) << "x = " << x << " [" << t.name << "]: miss";
      EXPECT_EQ((*hit)->voxel, glm::i64vec3(14, 100, 100)) << x;
    }
  }
}

// IsValidRay (the traversal's inline check) accepts exactly the rays
// ValidateRay accepts, on every component at and around each limit.
TEST(FarOrigins, InlineRayCheckAgreesWithValidateRay) {
  const double inf = std::numeric_limits<double>::infinity();
  const double values[] = {0.0, -0.0, 1.0, -1.0, 1e-310, 0x1p1000, -0x1p1000,
                           std::nextafter(0x1p1000, inf), -std::nextafter(0x1p1000, inf),
                           1e302, std::numeric_limits<double>::max(), inf, -inf,
                           std::numeric_limits<double>::quiet_NaN()};
  int accepted = 0, refused = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (bool in_dir : {false, true})
      for (double v : values) {
        Ray r{{0.5, 0.5, 0.5}, {0.0, 0.0, 0.0}};
        r.dir[(axis + 1) % 3] = in_dir && v == 0.0 ? 0.0 : 1.0;  // (0, 0, 0) when v is zero
        (in_dir ? r.dir : r.origin)[axis] = v;
        const bool ok = ValidateRay(r).ok();
        EXPECT_EQ(IsValidRay(r), ok) << RayString(r);
        (ok ? accepted : refused)++;
      }
  EXPECT_GT(accepted, 20);
  EXPECT_GT(refused, 10);
}

TEST(FarOrigins, OriginsBeyondTheDocumentedRangeAreRefused) {
  EXPECT_TRUE(ValidateRay(Ray{{1e300, 0.5, 0.5}, {-1, 0, 0}}).ok());
  const Status s = ValidateRay(Ray{{0.5, -1e302, 0.5}, {0, 1, 0}});
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("2^1000"), std::string::npos) << s.ToString();
  std::vector<Voxel> voxels = {{1, 1, 1}};
  Case c(voxels, 4, {4}, {4});
  auto hit = c.tracers[0].tracer.FirstHit(Ray{{1e308, 1.5, 1.5}, {-1, 0, 0}});
  EXPECT_FALSE(hit.ok());
}

}  // namespace
}  // namespace vox::testing

// Fog's exponentials (render/internal/fog_math.h) against libm's exp and
// expm1 across the polynomials' range, its edges and beyond, and the
// curvature's share against its integral; the light lattice's caches, of
// points and of light-space columns, and their blocks
// (render/internal/fog_light.h); the light's integral along a primary ray
// (render/internal/light_along_ray.h) against a quadrature.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>
#include <limits>

#include "render/internal/fog_light.h"
#include "render/internal/fog_math.h"
#include "render/internal/light_along_ray.h"

namespace vox::render_internal {
namespace {

TEST(FogMathTest, MatchesLibm) {
  const double edge = kSmallExponent;
  for (double x : {0.0, -0.0, 1e-300, 1e-12, 3e-7, 0.004, 0.03, edge * 0.999, edge, 0.2, 3.0, 40.0}) {
    for (double sx : {x, -x}) {
      const double e = std::exp(-sx);
      EXPECT_NEAR(ExpNeg(sx), e, 1e-15 * e) << sx;
      const double share = sx == 0 ? 1.0 : -std::expm1(-sx) / sx;
      EXPECT_NEAR(ExpNegShare(sx), share, 1e-15 * share) << sx;
    }
  }
  // A sweep of the polynomials' range.
  for (int i = -1000; i <= 1000; ++i) {
    const double x = edge * i / 1000.0;
    EXPECT_NEAR(ExpNeg(x), std::exp(-x), 1e-15 * std::exp(-x)) << x;
    const double share = x == 0 ? 1.0 : -std::expm1(-x) / x;
    EXPECT_NEAR(ExpNegShare(x), share, 1e-15 * share) << x;
  }
  EXPECT_EQ(ExpNeg(std::numeric_limits<double>::infinity()), 0.0);
  EXPECT_TRUE(std::isnan(ExpNeg(std::nan(""))));
  EXPECT_TRUE(std::isnan(ExpNegShare(std::nan(""))));
}

// CurveShareOf(x, e^-x) is the integral of e^(-x u) u (u - 1) over [0, 1]
// (Simpson's rule here), on both sides of where its series takes over.
TEST(FogMathTest, CurveShareMatchesItsIntegral) {
  for (double x : {0.0, 1e-9, 1e-4, 0.01, 0.2, 0.2499, 0.25, 0.26, 1.0, 7.0, -1e-4, -0.2, -0.25, -0.3, -2.0}) {
    const int n = 20000;
    double sum = 0;
    for (int i = 0; i <= n; ++i) {
      const double u = double(i) / n, w = i == 0 || i == n ? 1 : i % 2 ? 4 : 2;
      sum += w * std::exp(-x * u) * u * (u - 1.0);
    }
    const double want = sum / (3.0 * n);
    EXPECT_NEAR(CurveShareOf(x, std::exp(-x)), want, 1e-7 * std::fabs(want)) << x;
  }
}

// The light lattice's cache (render/internal/fog_light.h): every block it
// answers holds the light at its eight points whatever was asked before,
// through its block table, its points' table, restarts when full and
// indices too far to keep; each point is computed once while kept.
TEST(FogLightCacheTest, AnswersDoNotDependOnWhatWasAskedBefore) {
  auto value = [](const glm::dvec3& q) { return glm::dvec3(q.x + 1e3 * q.y, q.z, -q.x); };
  FogLightCache cache;
  int calls = 0;
  auto light = [&](const glm::dvec3& q, glm::dvec3* out) {
    ++calls;
    *out = value(q);
    return true;
  };
  std::mt19937_64 rng(7);
  std::vector<glm::i64vec3> blocks;
  for (int i = 0; i < 64; ++i)
    blocks.push_back(glm::i64vec3(int64_t(rng() % 9) - 4, int64_t(rng() % 9) - 4, int64_t(rng() % 9) - 4));
  blocks.push_back(glm::i64vec3(int64_t(1) << 40, 0, 0));  // too far to keep
  int far_asks = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (int trial = 0; trial < 4000; ++trial) {
      const glm::i64vec3 i0 = blocks[rng() % blocks.size()];
      far_asks += pass == 1 && i0.x > 1000;
      const int level = int(rng() % 3);
      const LatticeBlock* b = cache.Block(level, i0, light);
      ASSERT_NE(b, nullptr);
      const double s = std::ldexp(1.0, level);
      for (int c = 0; c < 8; ++c) {
        const glm::dvec3 q((double(i0.x + (c & 1)) + 0.5) * s + kLatticeOffset,
                           (double(i0.y + ((c >> 1) & 1)) + 0.5) * s + kLatticeOffset,
                           (double(i0.z + ((c >> 2) & 1)) + 0.5) * s + kLatticeOffset);
        for (int k = 0; k < 3; ++k)
          ASSERT_EQ(b->log_light[k][c], value(q)[k]) << "trial " << trial << ", corner " << c;
      }
    }
    // Kept points are not computed again (these few never fill the cache):
    // the second pass computes only the far block's points, each time.
    if (pass == 0) calls = 0;
  }
  EXPECT_GT(far_asks, 0);
  EXPECT_EQ(calls, 8 * far_asks);
  // A failing light keeps nothing: the block is computed again next time.
  FogLightCache failing;
  int n = 0;
  EXPECT_EQ(failing.Block(0, glm::i64vec3(0), [&](const glm::dvec3&, glm::dvec3*) { return ++n < 4; }),
            nullptr);
  n = 0;
  const LatticeBlock* b = failing.Block(0, glm::i64vec3(0), light);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(b->log_light[2][7], value(glm::dvec3(1.5 + kLatticeOffset)).z);
}

// The light-space lattice's columns (FogColumnCache): every sample it
// answers is its column's depth whatever was asked before, through restarts
// when full; samples are traced in chunks from the top, each from the depth
// before it, once while kept; a failing trace keeps nothing. Blocks hold
// their corners' depths, negated.
TEST(FogColumnCacheTest, AnswersDoNotDependOnWhatWasAskedBefore) {
  // Column (i, j)'s depth grows by step(i, j, k) from sample k - 1 to k.
  auto step = [](int64_t i, int64_t j, int k) { return 1e-3 * double((i * 7 + j * 13 + k) % 11); };
  auto depth = [&](int64_t i, int64_t j, int k) {
    double d = 0;
    for (int q = 1; q <= k; ++q) d += step(i, j, q);
    return d;
  };
  int traced = 0;
  auto trace = [&](int64_t i, int64_t j, int first, int count, const glm::dvec3& d0, glm::dvec3* out) {
    EXPECT_EQ(first % FogColumnCache::kChunk, 0);
    EXPECT_EQ(count, FogColumnCache::kChunk);
    traced += count;
    glm::dvec3 d = d0;
    for (int q = 0; q < count; ++q) out[q] = d += glm::dvec3(step(i, j, first + 1 + q));
    return true;
  };
  FogColumnCache cache;
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 3000; ++trial) {
    const int64_t i = int64_t(rng() % 40) - 20, j = int64_t(rng() % 40) - 20;
    const int last = int(rng() % 900), level = int(rng() % 2);
    const glm::dvec3* d = cache.Samples(level, i, j, last, [&](int f, int n, const glm::dvec3& d0, glm::dvec3* o) {
      return trace(i, j, f, n, d0, o);
    });
    ASSERT_NE(d, nullptr);
    for (int k : {0, last / 2, last}) ASSERT_NEAR(d[k].x, depth(i, j, k), 1e-12) << i << " " << j << " " << k;
  }
  // (3000 columns of up to 900 samples fill the cache several times over.)
  EXPECT_GT(traced, int(FogColumnCache::kMaxSamples));
  // A kept column is not traced again.
  traced = 0;
  auto again = [&](int f, int n, const glm::dvec3& d0, glm::dvec3* o) { return trace(3, 4, f, n, d0, o); };
  cache.Samples(0, 3, 4, 40, again);
  const int first = traced;
  cache.Samples(0, 3, 4, 40, again);
  EXPECT_EQ(traced, first);
  // A block's corners: columns (i0, j0)..(i0 + 1, j0 + 1), samples m0, m0 + 1.
  const ColumnBlock* b = cache.Block(1, -2, 5, 30, trace);
  ASSERT_NE(b, nullptr);
  for (int c = 0; c < 8; ++c)
    EXPECT_NEAR(b->ch[0].log_light[c], -depth(-2 + (c & 1), 5 + ((c >> 1) & 1), 30 + (c >> 2)), 1e-12) << c;
  // A failing trace keeps nothing: the column is traced again next time.
  FogColumnCache failing;
  int calls = 0;
  EXPECT_EQ(failing.Samples(0, 0, 0, 50, [&](int, int, const glm::dvec3&, glm::dvec3*) { return ++calls < 3; }),
            nullptr);
  const glm::dvec3* d = failing.Samples(0, 0, 0, 50, [&](int f, int n, const glm::dvec3& d0, glm::dvec3* o) {
    return trace(0, 0, f, n, d0, o);
  });
  ASSERT_NE(d, nullptr);
  EXPECT_NEAR(d[50].x, depth(0, 0, 50), 1e-12);
}

// A column block measures the log-light's curvature across the columns at
// its edges from the columns beside it: for optical depths quadratic across
// the columns, the second differences exactly. A column beside it whose
// light differs by more than a factor of e from the block's (a shadow's
// edge) leaves the block without it.
TEST(FogColumnCacheTest, BlocksMeasureTheCurvatureAcrossColumns) {
  const double a = 1e-3, b = 3e-4;  // per sample, per column index squared
  bool steep_column = false;
  auto depth = [&](int64_t i, int64_t j, int m) {
    if (steep_column && i == 2) return 5.0;
    return m * (0.01 + a * double(i * i) + b * double(j * j));
  };
  auto trace = [&](int64_t i, int64_t j, int first, int count, const glm::dvec3&, glm::dvec3* out) {
    for (int q = 0; q < count; ++q) out[q] = glm::dvec3(depth(i, j, first + 1 + q));
    return true;
  };
  FogColumnCache cache;
  const int64_t i0 = 3, j0 = -4;
  const int m0 = 7;
  const ColumnBlock* blk = cache.Block(0, i0, j0, m0, trace);
  ASSERT_NE(blk, nullptr);
  ASSERT_TRUE(blk->curved);
  for (int m = 0; m < 2; ++m)
    for (int r = 0; r < 2; ++r) {
      // (log-light: minus the depth; second differences of m (a i^2 + b j^2))
      EXPECT_NEAR(blk->ch[0].curve_u[r + 2 * m], -2 * a * (m0 + m), 1e-12) << r << " " << m;
      EXPECT_NEAR(blk->ch[0].curve_v[r + 2 * m], -2 * b * (m0 + m), 1e-12) << r << " " << m;
    }
  // (the range of the twelve columns' light: the deepest and shallowest)
  EXPECT_NEAR(blk->ch[0].lo, -depth(5, -4, m0 + 1), 1e-12);
  EXPECT_NEAR(blk->ch[0].hi, -depth(2, -3, m0), 1e-12);
  // A column beside the block across a shadow's edge: no curvature (a new
  // cache: the block is kept).
  steep_column = true;
  FogColumnCache other;
  const ColumnBlock* near_edge = other.Block(0, 0, j0, m0, trace);  // (column 2 is beside it)
  ASSERT_NE(near_edge, nullptr);
  EXPECT_NE(near_edge->shape, LatticeBlock::kSteep);
  EXPECT_FALSE(near_edge->curved);
}

// The light's integral along a primary ray (LightAlongRay::Integrate) in
// fog of even density, cell by cell, where the light's logarithm is curved
// along the ray (its optical depth grows as a square root, as inside a
// round fog towards its rim seen from the light): within 0.1% of a
// quadrature with samples 24 apart. Interpolated straight in the logarithm
// between the samples it would see too much light all along the ray
// (0.6% here).
TEST(LightAlongRayTest, FollowsTheLightsCurvature) {
  const double st = 0.02, cell = 4.0, end = 240.0;
  auto tau = [](double t) { return 3.0 * std::sqrt(1.0 + t / 60.0); };
  int samples = 0;
  LightAlongRay light(
      [&](double t, double, double* max_step) {
        ++samples;
        *max_step = 1e300;
        return glm::dvec3(std::exp(-tau(t)));
      },
      1.0);
  double got = 0, trans = 1;
  for (double t0 = 0; t0 < end; t0 += cell) {
    double one_piece_trans = 0;
    bool one_piece = false;
    const double in = light.Integrate(t0, t0 + cell, st, trans, [](double, double) { return 24.0; },
                                      &one_piece_trans, &one_piece);
    got += trans * in;
    trans *= std::exp(-st * cell);
  }
  const int n = 200000;
  double want = 0;
  for (int i = 0; i < n; ++i) {
    const double t = (i + 0.5) * end / n;
    want += st * std::exp(-st * t) * std::exp(-tau(t)) * end / n;
  }
  EXPECT_LT(samples, 20);
  EXPECT_NEAR(got, want, 1e-3 * want);
}

// A block's shape: grey when its three channels agree everywhere, steep when
// a channel's corners span more than kMaxLatticeLogRatio or only some have
// light, and channels without light anywhere marked dark.
TEST(LatticeBlockTest, ClassifiesItsCorners) {
  const double inf = std::numeric_limits<double>::infinity();
  glm::dvec3 c[8];
  for (int i = 0; i < 8; ++i) c[i] = glm::dvec3(-0.1 * i);
  LatticeBlock b;
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kGrey);
  EXPECT_FALSE(b.dark[0] || b.dark[1] || b.dark[2]);
  EXPECT_EQ(b.log_light[1][3], -0.1 * 3);
  c[7] = glm::dvec3(-0.1 * 7 - 0.4);  // a span of 1.1
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kSteep);
  c[7] = glm::dvec3(-kMaxLatticeLogRatio);  // a span of exactly the ratio
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kGrey);
  for (int i = 0; i < 8; ++i) c[i] = glm::dvec3(-0.1 * i, -inf, -0.2);  // green dark everywhere
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kRgb);
  EXPECT_TRUE(b.dark[1]);
  EXPECT_FALSE(b.dark[0] || b.dark[2]);
  c[4].z = -inf;  // blue dark at one corner only
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kSteep);
  for (int i = 0; i < 8; ++i) c[i] = glm::dvec3(-inf);  // no light anywhere
  b.Set(c);
  EXPECT_EQ(b.shape, LatticeBlock::kGrey);
  EXPECT_TRUE(b.dark[0] && b.dark[1] && b.dark[2]);
}

}  // namespace
}  // namespace vox::render_internal

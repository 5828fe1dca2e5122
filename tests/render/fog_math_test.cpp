// Fog's exponentials (render/internal/fog_math.h) against libm's exp and
// expm1 across the polynomials' range, its edges and beyond.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "render/internal/fog_math.h"

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

}  // namespace
}  // namespace vox::render_internal

// Fog's exponentials. A primary ray through fog crosses hundreds of cells,
// each of a small optical depth (a few thousandths on the measured frames):
// there a short Taylor polynomial is as accurate as libm's exp and several
// times cheaper; larger arguments go to libm.
//
// Thread safety: pure functions.
#ifndef VOX_RENDER_INTERNAL_FOG_MATH_H_
#define VOX_RENDER_INTERNAL_FOG_MATH_H_

#include <cmath>

namespace vox::render_internal {

// |x| below this uses the polynomials (degree 9): their truncation error is
// below x^10 / 10! < 3e-19, under the rounding of a double.
inline constexpr double kSmallExponent = 1.0 / 16.0;

// c[0] + c[1] y + ... + c[9] y^9 by Estrin's scheme: pairs of terms and
// powers y^2, y^4, y^8 computed side by side, four dependent steps deep
// where Horner's rule takes nine (the fog's integration waits on its
// exponentials one after another along a ray).
inline double Poly9(double y, const double (&c)[10]) {
  const double y2 = y * y, y4 = y2 * y2, y8 = y4 * y4;
  const double p01 = c[0] + c[1] * y, p23 = c[2] + c[3] * y, p45 = c[4] + c[5] * y;
  const double p67 = c[6] + c[7] * y, p89 = c[8] + c[9] * y;
  return (p01 + p23 * y2) + (p45 + p67 * y2) * y4 + p89 * y8;
}

// e^(-x).
inline double ExpNeg(double x) {
  if (!(std::abs(x) < kSmallExponent)) return std::exp(-x);
  // 1 - x + x^2/2! - ... - x^9/9!.
  static constexpr double c[10] = {1.0,       1.0,        1.0 / 2,     1.0 / 6,      1.0 / 24,
                                   1.0 / 120, 1.0 / 720,  1.0 / 5040,  1.0 / 40320,  1.0 / 362880};
  return Poly9(-x, c);
}

// (1 - e^(-x)) / x, and 1 at x = 0: the share of a cell of optical depth x
// that a ray's light loses in it per unit of optical depth (exact for small
// x, where 1 - e^(-x) would lose its digits).
inline double ExpNegShare(double x) {
  if (!(std::abs(x) < kSmallExponent)) return -std::expm1(-x) / x;
  // 1 - x/2! + x^2/3! - ... - x^9/10!.
  static constexpr double c[10] = {1.0,        1.0 / 2,     1.0 / 6,      1.0 / 24,      1.0 / 120,
                                   1.0 / 720,  1.0 / 5040,  1.0 / 40320,  1.0 / 362880,  1.0 / 3628800};
  return Poly9(-x, c);
}

// ExpNegShare(x) given e = e^(-x) (as ExpNeg gives it): (1 - e) / x where
// that keeps at least 12 digits, the series where x is too small for it.
inline double ExpNegShareOf(double x, double e) {
  if (!(std::abs(x) < 1e-3)) return (1.0 - e) / x;
  return 1.0 - x * (1.0 / 2 - x * (1.0 / 6 - x * (1.0 / 24 - x * (1.0 / 120))));
}

// (2 - x - (2 + x) e) / x^3 given e = e^(-x): the integral of e^(-x u) u
// (u - 1) over u in [0, 1], the share of a quadratic's bend u (u - 1) in
// a piece of optical depth x (-1/6 at x = 0). The series where the closed
// form would lose its digits (its truncation error is below x^6 / 50000).
inline double CurveShareOf(double x, double e) {
  if (!(std::abs(x) < 0.25)) return (2.0 - x - (2.0 + x) * e) / (x * x * x);
  return -1.0 / 6 + x * (1.0 / 12 - x * (1.0 / 40 - x * (1.0 / 180 - x * (1.0 / 1008 - x * (1.0 / 6720)))));
}

}  // namespace vox::render_internal

#endif  // VOX_RENDER_INTERNAL_FOG_MATH_H_

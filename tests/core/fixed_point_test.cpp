// FixedPoint<Word, Frac> against GMP: FromReal rounds x * 2^Frac, Floor is
// the mathematical floor, Ratio is round(|num / den| * 2^Frac) exactly (half
// up) or saturates, for the three word sizes of the accuracy study.
#include <gmpxx.h>
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <random>

#include "core/fixed_point.h"

namespace vox {
namespace {

mpz_class FromInt128(__int128 v) {
  const bool neg = v < 0;
  unsigned __int128 u = neg ? -(unsigned __int128)v : (unsigned __int128)v;
  mpz_class hi, lo;
  mpz_set_ui(hi.get_mpz_t(), (unsigned long)(uint64_t)(u >> 64));
  mpz_set_ui(lo.get_mpz_t(), (unsigned long)(uint64_t)u);
  mpz_class r = (hi << 64) + lo;
  return neg ? mpz_class(-r) : r;
}

// x exactly, as a rational (long double: 64-bit significand).
mpq_class Exact(long double x) {
  if (x == 0) return 0;
  int e = 0;
  long double m = std::frexp(std::fabs(x), &e);  // [0.5, 1)
  uint64_t bits = uint64_t(std::ldexp(m, 64));
  mpz_class z;
  mpz_set_ui(z.get_mpz_t(), (unsigned long)bits);
  mpq_class q(z);
  if (e - 64 >= 0) {
    q *= mpq_class(mpz_class(1) << (e - 64));
  } else {
    q /= mpq_class(mpz_class(1) << (64 - e));
  }
  return x < 0 ? mpq_class(-q) : q;
}

mpz_class Floor(const mpq_class& q) {
  mpz_class r;
  mpz_fdiv_q(r.get_mpz_t(), q.get_num_mpz_t(), q.get_den_mpz_t());
  return r;
}

template <class F>
class FixedPointTest : public ::testing::Test {};
using Formats = ::testing::Types<Fixed32, Fixed64, Fixed128>;
TYPED_TEST_SUITE(FixedPointTest, Formats);

TYPED_TEST(FixedPointTest, FromIntAndFloorAreExact) {
  using F = TypeParam;
  std::mt19937_64 rng(1);
  const int64_t lim = int64_t(1) << (F::kIntBits - 2);
  for (int i = 0; i < 20000; ++i) {
    int64_t v = int64_t(rng() % uint64_t(2 * lim)) - lim;
    typename F::Word w = F::FromInt(v);
    EXPECT_EQ(FromInt128(w), mpz_class(v) * (mpz_class(1) << F::kFrac));
    EXPECT_EQ(F::Floor(w), v);
    // Floor of values between integers, including negative ones.
    typename F::Word frac = typename F::Word(rng() % (uint64_t(1) << std::min(F::kFrac, 62)));
    if (F::kFrac > 62) frac <<= (F::kFrac - 62);
    typename F::Word x = w + frac;
    mpq_class exact(FromInt128(x), mpz_class(1) << F::kFrac);
    EXPECT_EQ(mpz_class(F::Floor(x)), Floor(exact)) << v;
    EXPECT_EQ(F::template ToReal<long double>(w), (long double)v);
  }
}

TYPED_TEST(FixedPointTest, FromRealRoundsToNearest) {
  using F = TypeParam;
  std::mt19937_64 rng(2);
  const long double lim = std::ldexp(1.0L, F::kIntBits - 2);
  for (int i = 0; i < 50000; ++i) {
    long double x;
    switch (i % 5) {
      case 0:  // uniform over the range, full 64-bit significand
        x = (long double)(rng() >> 1) / std::ldexp(1.0L, 63) * 2 * lim - lim;
        break;
      case 1:  // small magnitudes
        x = std::ldexp((long double)(rng() | 1), -int(rng() % 120) - 64) * (rng() & 1 ? 1 : -1);
        break;
      case 2:  // exact halves of the last unit: ties
        x = std::ldexp((long double)(int64_t(rng() % 4096) - 2048) + 0.5L, -F::kFrac);
        break;
      case 3:  // integers and dyadic values
        x = std::ldexp((long double)(int64_t(rng() % 100000) - 50000), -int(rng() % 30));
        break;
      default:  // just below / above a unit boundary
        x = std::ldexp((long double)(int64_t(rng() % 4096) - 2048) + 0.5L, -F::kFrac);
        x = std::nextafter(x, rng() & 1 ? lim : -lim);
        break;
    }
    if (!(std::fabs(x) < lim)) continue;
    const mpq_class y = Exact(x) * mpq_class(mpz_class(1) << F::kFrac);
    const mpz_class got = FromInt128(F::FromReal(x));
    const mpq_class err = mpq_class(got) - y;
    // Round to nearest: |error| <= 1/2 unit (ties either way).
    ASSERT_LE(abs(err), mpq_class(1, 2))
        << "x = " << std::hexfloat << x << " (kind " << i % 5 << "), error " << err.get_d()
        << " units";
  }
}

TYPED_TEST(FixedPointTest, RatioIsExactlyRounded) {
  using F = TypeParam;
  using Word = typename F::Word;
  std::mt19937_64 rng(3);
  const Word sat = F::FromInt(int64_t(1) << (F::kIntBits - 3));
  const mpz_class sat_z = FromInt128(sat);
  auto random_double = [&](int emin, int emax) {
    double m = double(rng() >> 11) * 0x1p-53 + 0.5;  // [0.5, 1.5)
    return std::ldexp(m, emin + int(rng() % uint64_t(emax - emin + 1))) * (rng() & 1 ? 1 : -1);
  };
  for (int i = 0; i < 50000; ++i) {
    double num = random_double(-30, 30), den = random_double(-30, 30);
    switch (i % 6) {
      case 0: den = num * double(rng() % 7 + 1); break;  // simple ratios
      case 1: den = random_double(-1074, -1022); break;  // subnormal / tiny den
      case 2: num = random_double(-1074, -1000); break;  // tiny quotient
      case 3: den = 0.0; break;
      case 4: num = std::ldexp(double(rng() % 1000 + 1), 0); den = double(rng() % 1000 + 1); break;
      default: break;
    }
    const Word got = F::Ratio(num, den, sat);
    if (den == 0) {
      EXPECT_EQ(got, sat);
      continue;
    }
    const mpq_class q = abs(mpq_class(num) / mpq_class(den));
    const mpz_class rounded = Floor(q * mpq_class(mpz_class(1) << F::kFrac) + mpq_class(1, 2));
    if (q >= mpq_class(mpz_class(1) << (F::kIntBits - 2)) || rounded >= sat_z) {
      EXPECT_EQ(got, sat) << num << " / " << den;
    } else {
      EXPECT_EQ(FromInt128(got), rounded) << num << " / " << den;
    }
  }
}

TEST(FixedPoint, Fixed128KeepsTinyFractions) {
  // 2^-100 * 2^103 = 8 units: all of long double's precision must survive.
  EXPECT_EQ(Fixed128::FromReal(std::ldexp(1.0L, -100)), __int128(8));
  EXPECT_EQ(Fixed128::FromReal(1.0L + std::ldexp(1.0L, -63)),
            (__int128(1) << 103) + (__int128(1) << 40));
  EXPECT_EQ(Fixed64::FromReal(-0.75L), -(int64_t(3) << 37));
  EXPECT_EQ(Fixed32::FromReal(2.5L / 128), 3);  // 2.5 units: ties round away from zero
}

}  // namespace
}  // namespace vox

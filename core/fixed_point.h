// vox::FixedPoint<Word, Frac>: the fixed-point numbers of the paper's DDA.
//
// A value x is stored as the integer round(x * 2^Frac) in a signed Word
// (int32_t, int64_t or __int128). Only what the DDA needs is defined: exact
// conversion from integers, rounding conversion from floating point, floor,
// and an exactly rounded quotient of two doubles (the inverse slopes).
// Stateless; thread-safe.
#ifndef VOX_CORE_FIXED_POINT_H_
#define VOX_CORE_FIXED_POINT_H_

#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace vox {

template <typename WordT, int kFracBits>
struct FixedPoint {
  using Word = WordT;
  static constexpr int kBits = int(sizeof(Word) * 8);
  static constexpr int kFrac = kFracBits;
  static_assert(kFrac >= 0 && kFrac < kBits - 2 && (kBits <= 64 || kFrac >= 62), "fractional bits must leave room for an integer part");

  // Largest magnitude of integer part the word holds: 2^(kBits - 1 - kFrac).
  static constexpr int kIntBits = kBits - 1 - kFrac;

  static constexpr Word FromInt(int64_t i) { return Word(i) * (Word(1) << kFrac); }
  static constexpr int64_t Floor(Word w) { return int64_t(w >> kFrac); }

  // round(x * 2^Frac), ties away from zero. REQUIRES: |x| < 2^(kIntBits - 1), finite.
  template <typename Real>
  static Word FromReal(Real x) {
    if constexpr (kBits <= 64) {
      // x * 2^Frac is exact (a power of two) and fits in 63 bits. Rounding
      // by the exact remainder, not by y + 0.5 (which itself rounds: y just
      // below k + 1/2 became k + 1).
      Real y = x * Real(uint64_t(1) << kFrac);
      int64_t t = int64_t(y);  // toward zero
      Real r = y - Real(t);    // exact, in (-1, 1)
      return Word(t + (r >= Real(0.5)) - (r <= Real(-0.5)));
    } else {
      // Integer part, then the fraction in two exact chunks (62 bits, then
      // the remaining kFrac - 62), rounded once: a 128-bit word gets all the
      // precision that `Real` has, also for values far below 1. On |x|:
      // x - floor(x) is not exact for small negative x.
      const bool neg = x < 0;
      const Real ax = neg ? -x : x;
      using std::floor;  // and ExactReal's, found by ADL
      Real ip = floor(ax);
      Real f = (ax - ip) * Real(uint64_t(1) << 62);  // exact, in [0, 2^62)
      int64_t hi = int64_t(f);                        // floor, as f >= 0
      Real lo = (f - Real(hi)) * Real(uint64_t(1) << (kFrac - 62));  // exact
      int64_t lo_i = int64_t(lo);
      lo_i += (lo - Real(lo_i)) >= Real(0.5);
      const Word w = Word(int64_t(ip)) * (Word(1) << kFrac) +
                     Word(hi) * (Word(1) << (kFrac - 62)) + Word(lo_i);
      return neg ? -w : w;
    }
  }

  template <typename Real>
  static Real ToReal(Word w) {
    // Two halves, so a 128-bit word converts without losing its high bits.
    int64_t ip = Floor(w);
    Word frac = w - FromInt(ip);
    constexpr int kShift = kFrac > 62 ? 62 : kFrac;
    const int64_t m = int64_t(kFrac > 62 ? frac >> (kFrac - 62) : frac);
    Real f = 0;
    if constexpr (std::is_floating_point_v<Real>) {
      f = Real(m) * Real(1.0 / double(uint64_t(1) << kShift));  // exact power of two, no libm call
    } else {
      using std::ldexp;  // ExactReal's, found by ADL
      f = ldexp(Real(m), -kShift);
    }
    return Real(ip) + f;
  }

  // round(|num / den| * 2^Frac), exactly, or `sat` if that is >= sat or den
  // is zero. Used for the inverse slopes q = |D_d / D_j|, so their only error
  // is the final rounding, whatever floating-point type the rest uses.
  static Word Ratio(double num, double den, Word sat) {
    num = std::fabs(num);
    den = std::fabs(den);
    static_assert(kIntBits - 2 < 64);
    constexpr double kLimit = double(uint64_t(1) << (kIntBits - 2));
    // num/den may overflow to inf for subnormal den: saturate.
    const double quotient = num / den;
    if (den == 0.0 || !(quotient < kLimit)) return sat;
    if (num == 0.0) return 0;
    if constexpr (kBits <= 64) {
      // The common case without a division of integers: c = floor(x + 1/2),
      // x = num / den * 2^Frac, from the double quotient (off by less than
      // 1/2 while x < 2^52, so c by at most 1), checked and corrected
      // exactly: (2c - 1) md <= 2x md < (2c + 1) md, all below 2^106
      // (num = mn 2^(en - 53), den = md 2^(ed - 53), both normal here).
      const double y = quotient * double(uint64_t(1) << kFrac);
      uint64_t bn, bd;
      std::memcpy(&bn, &num, sizeof bn);
      std::memcpy(&bd, &den, sizeof bd);
      const int en = int(bn >> 52), ed = int(bd >> 52);  // biased exponents (sign is 0)
      const int shift = kFrac + 1 + (en - ed);
      if (y < 0x1p52 && en != 0 && ed != 0 && shift >= 0 && shift <= 127 - 53) {
        using U = unsigned __int128;
        constexpr uint64_t kHidden = uint64_t(1) << 52;
        const uint64_t mn = (bn & (kHidden - 1)) | kHidden, md = (bd & (kHidden - 1)) | kHidden;
        uint64_t c = uint64_t(y + 0.5);
        const U two_x = U(mn) << shift;  // 2x md
        if (c > 0 && two_x < U(2 * c - 1) * md)
          --c;
        else if (two_x >= U(2 * c + 1) * md)
          ++c;
        const Word w = Word(c);
        return w >= sat ? sat : w;
      }
    }
    return RatioByDivision(num, den, sat);
  }

 private:
  // Ratio's exact quotient by division (num, den > 0 and finite).
  [[gnu::noinline]] static Word RatioByDivision(double num, double den, Word sat) {
    int en = 0, ed = 0;
    // num = mn * 2^(en - 53), den = md * 2^(ed - 53), mn, md 53-bit integers.
    uint64_t mn = Mantissa53(num, &en);
    uint64_t md = Mantissa53(den, &ed);
    // Quotient = (mn / md) * 2^(en - ed); we want it * 2^Frac, plus one more
    // bit for rounding: long division, one quotient bit per step.
    int shift = kFrac + 1 + (en - ed);  // total power of two applied to mn / md
    if (shift < -64) return 0;
    unsigned __int128 q = 0;
    if (shift >= 0 && shift <= 127 - 53) {
      q = (static_cast<unsigned __int128>(mn) << shift) / md;  // one 128-bit division
    } else {
      // Long division, one quotient bit per step (128-bit words).
      unsigned __int128 rem = mn;
      q = rem / md;  // 0 or 1: mn, md are both in [2^52, 2^53)
      rem -= q * md;
      if (shift >= 0) {
        for (int i = 0; i < shift; ++i) {
          rem <<= 1;
          q <<= 1;
          if (rem >= md) {
            rem -= md;
            q |= 1;
          }
        }
      } else {
        q >>= -shift;
      }
    }
    q = (q + 1) >> 1;  // round half up on the extra bit
    Word w = Word(q);
    return w >= sat ? sat : w;
  }

  // x = m * 2^(e - 53) with m in [2^52, 2^53), for finite x > 0 (as
  // frexp(x, &e) * 2^53, by the bits for normal x, without libm calls).
  static uint64_t Mantissa53(double x, int* e) {
    uint64_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    const int biased = int(bits >> 52) & 0x7ff;
    if (biased == 0) return uint64_t(std::ldexp(std::frexp(x, e), 53));  // subnormal
    *e = biased - 1022;
    return (bits & ((uint64_t(1) << 52) - 1)) | (uint64_t(1) << 52);
  }
};

// The word sizes of the accuracy study. Frac is chosen so that a step of up
// to 20 levels fits (oriented coordinates and saturated slopes stay below
// 2^23 in magnitude; see tracer.h).
using Fixed32 = FixedPoint<int32_t, 7>;
using Fixed64 = FixedPoint<int64_t, 39>;
using Fixed128 = FixedPoint<__int128, 103>;

}  // namespace vox

#endif  // VOX_CORE_FIXED_POINT_H_

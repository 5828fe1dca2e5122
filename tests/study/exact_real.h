// vox::ExactReal: exact rational arithmetic (GMP) with IEEE-style infinities
// and NaN, so the tracer's per-ray set-up and transition can run exactly for
// the accuracy study (Tracer<Fixed, ExactReal>). Only what the tracer uses is
// defined. Slow by design: a study variant, not a rendering path.
// Value type; thread-compatible.
#ifndef VOX_TESTS_STUDY_EXACT_REAL_H_
#define VOX_TESTS_STUDY_EXACT_REAL_H_

#include <gmpxx.h>

#include <cmath>
#include <cstdint>
#include <limits>

namespace vox {

class ExactReal {
 public:
  ExactReal() = default;
  ExactReal(int v) : q_(v) {}                   // NOLINT: implicit, like a double
  ExactReal(long v) : q_(v) {}                  // NOLINT
  ExactReal(long long v) : q_(static_cast<long>(v)) {}  // NOLINT (long is 64-bit here)
  ExactReal(unsigned long v) : q_(v) {}         // NOLINT
  ExactReal(double v) {                         // NOLINT
    if (std::isnan(v)) kind_ = kNaN;
    else if (std::isinf(v)) kind_ = v > 0 ? kPosInf : kNegInf;
    else q_ = v;  // exact
  }

  bool finite() const { return kind_ == kFinite; }
  // Truncation toward zero. REQUIRES: finite, |value| < 2^63.
  explicit operator int64_t() const {
    mpz_class z(q_);  // truncates
    return static_cast<int64_t>(z.get_si());
  }
  explicit operator double() const {
    switch (kind_) {
      case kPosInf: return std::numeric_limits<double>::infinity();
      case kNegInf: return -std::numeric_limits<double>::infinity();
      case kNaN: return std::numeric_limits<double>::quiet_NaN();
      default: return q_.get_d();
    }
  }

  friend ExactReal operator+(const ExactReal& a, const ExactReal& b) {
    if (a.finite() && b.finite()) return ExactReal(mpq_class(a.q_ + b.q_));
    return ExactReal(double(a) + double(b));
  }
  friend ExactReal operator-(const ExactReal& a, const ExactReal& b) {
    if (a.finite() && b.finite()) return ExactReal(mpq_class(a.q_ - b.q_));
    return ExactReal(double(a) - double(b));
  }
  friend ExactReal operator-(const ExactReal& a) { return ExactReal(0) - a; }
  friend ExactReal operator*(const ExactReal& a, const ExactReal& b) {
    if (a.finite() && b.finite()) return ExactReal(mpq_class(a.q_ * b.q_));
    return ExactReal(SignOrZero(a) * SignOrZero(b) * Special(a, b));
  }
  friend ExactReal operator/(const ExactReal& a, const ExactReal& b) {
    if (a.finite() && b.finite()) {
      if (sgn(b.q_) == 0) return ExactReal(SignOrZero(a) == 0 ? std::nan("") : SignOrZero(a) * HUGE_VAL);
      return ExactReal(mpq_class(a.q_ / b.q_));
    }
    return ExactReal(double(a) / double(b));  // finite / inf -> 0, inf / inf -> NaN, ...
  }
  ExactReal& operator+=(const ExactReal& b) { return *this = *this + b; }
  ExactReal& operator-=(const ExactReal& b) { return *this = *this - b; }
  ExactReal& operator*=(const ExactReal& b) { return *this = *this * b; }

  friend bool operator<(const ExactReal& a, const ExactReal& b) { return Cmp(a, b) == -1; }
  friend bool operator>(const ExactReal& a, const ExactReal& b) { return Cmp(a, b) == 1; }
  friend bool operator<=(const ExactReal& a, const ExactReal& b) {
    int c = Cmp(a, b);
    return c == -1 || c == 0;
  }
  friend bool operator>=(const ExactReal& a, const ExactReal& b) {
    int c = Cmp(a, b);
    return c == 1 || c == 0;
  }
  friend bool operator==(const ExactReal& a, const ExactReal& b) { return Cmp(a, b) == 0; }
  friend bool operator!=(const ExactReal& a, const ExactReal& b) { return Cmp(a, b) != 0; }

  friend ExactReal fabs(const ExactReal& a) { return a < ExactReal(0) ? -a : a; }
  friend ExactReal floor(const ExactReal& a) {
    if (!a.finite()) return a;
    mpz_class z;
    mpz_fdiv_q(z.get_mpz_t(), a.q_.get_num_mpz_t(), a.q_.get_den_mpz_t());
    return ExactReal(mpq_class(z));
  }
  friend ExactReal ldexp(const ExactReal& a, int e) {
    if (!a.finite()) return a;
    mpq_class r = a.q_;
    if (e >= 0) mpq_mul_2exp(r.get_mpq_t(), r.get_mpq_t(), unsigned(e));
    else mpq_div_2exp(r.get_mpq_t(), r.get_mpq_t(), unsigned(-e));
    return ExactReal(r);
  }

 private:
  enum Kind : uint8_t { kFinite, kPosInf, kNegInf, kNaN };
  explicit ExactReal(const mpq_class& q) : q_(q) {}

  static int SignOrZero(const ExactReal& a) {
    switch (a.kind_) {
      case kPosInf: return 1;
      case kNegInf: return -1;
      case kNaN: return 0;
      default: return sgn(a.q_);
    }
  }
  // inf * x: NaN when either is NaN or a zero meets an infinity, else inf.
  static double Special(const ExactReal& a, const ExactReal& b) {
    if (a.kind_ == kNaN || b.kind_ == kNaN || SignOrZero(a) == 0 || SignOrZero(b) == 0)
      return std::nan("");
    return HUGE_VAL;
  }
  // -1, 0, 1, or 2 when unordered (NaN).
  static int Cmp(const ExactReal& a, const ExactReal& b) {
    if (a.kind_ == kNaN || b.kind_ == kNaN) return 2;
    if (a.finite() && b.finite()) {
      int c = cmp(a.q_, b.q_);
      return c < 0 ? -1 : c > 0 ? 1 : 0;
    }
    double x = double(a), y = double(b);
    return x < y ? -1 : x > y ? 1 : 0;
  }

  mpq_class q_{0};
  Kind kind_ = kFinite;
};

}  // namespace vox

namespace std {
template <>
class numeric_limits<vox::ExactReal> : public numeric_limits<double> {
 public:
  static vox::ExactReal infinity() { return vox::ExactReal(HUGE_VAL); }
};
}  // namespace std

#endif  // VOX_TESTS_STUDY_EXACT_REAL_H_

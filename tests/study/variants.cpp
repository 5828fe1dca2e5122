#include "tests/study/variants.h"

#include "core/fixed_point.h"
#include "core/tracer.h"
#include "tests/study/aw_tracer.h"
#include "tests/study/exact_real.h"

namespace vox {
namespace {

// Wraps any tracer with Create(view, n1) and FirstHit(ray, counters).
template <class T>
class Adapter : public AnyTracer {
 public:
  explicit Adapter(T t) : t_(std::move(t)) {}
  StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* c) const override {
    return t_.FirstHit(ray, c);
  }
  int n1() const override { return t_.n1(); }
  int n2() const override { return t_.n2(); }

  static StatusOr<std::unique_ptr<AnyTracer>> Create(const OctreeView& tree, int n1) {
    auto t = T::Create(tree, n1);
    if (!t.ok()) return t.status();
    return std::unique_ptr<AnyTracer>(new Adapter(std::move(t).value()));
  }

 private:
  T t_;
};

template <class Fixed, class Real>
TraversalVariant Paper(std::string family, std::string real) {
  TraversalVariant v;
  v.word_bits = Fixed::kBits;
  v.frac_bits = Fixed::kFrac;
  v.family = std::move(family);
  v.real = std::move(real);
  v.name = "fixed" + std::to_string(v.word_bits) + "/" + std::to_string(v.frac_bits) + " " + v.real;
  v.max_step_levels = std::min(kMaxStepLevels, Fixed::kIntBits - 3);
  v.create = &Adapter<Tracer<Fixed, Real>>::Create;
  return v;
}

template <class Real>
TraversalVariant Aw(std::string real) {
  TraversalVariant v;
  v.family = "amanatides-woo";
  v.real = real;
  v.name = "aw " + real;
  v.create = &Adapter<AwTracer<Real>>::Create;
  return v;
}

}  // namespace

std::vector<TraversalVariant> TraversalVariants() {
  using F64_16 = FixedPoint<int64_t, 16>;
  using F64_24 = FixedPoint<int64_t, 24>;
  using F64_32 = FixedPoint<int64_t, 32>;
  return {
      Paper<Fixed64, long double>("default", "long-double"),
      // Word size (the transition in long double).
      Paper<Fixed32, long double>("word", "long-double"),
      Paper<Fixed128, long double>("word", "long-double"),
      // Fractional bits of a 64-bit word.
      Paper<F64_16, long double>("frac", "long-double"),
      Paper<F64_24, long double>("frac", "long-double"),
      Paper<F64_32, long double>("frac", "long-double"),
      // The set-up and transition arithmetic.
      Paper<Fixed64, float>("transition", "float"),
      Paper<Fixed64, double>("transition", "double"),
      Paper<Fixed64, ExactReal>("transition", "exact"),
      Paper<Fixed128, ExactReal>("transition", "exact"),
      // The floating-point DDA the paper argued against.
      Aw<float>("float"),
      Aw<double>("double"),
      Aw<long double>("long-double"),
  };
}

}  // namespace vox

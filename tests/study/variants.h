// Traversal variants for the accuracy/time study (vox-study): the paper's
// tracer with other fixed-point words and fractional bits, its transition in
// other floating-point types or in exact rational arithmetic, and the
// floating-point 3D DDA of Amanatides and Woo that the paper argued against,
// all walking the same octree with the same skip loop and ascent, so only
// the arithmetic differs. Type-erased behind AnyTracer (one virtual call per
// ray) so a benchmark can loop over them.
//
// Thread safety: an AnyTracer is immutable; FirstHit is const and
// thread-safe when the tree's BrickSource is.
#ifndef VOX_TESTS_STUDY_VARIANTS_H_
#define VOX_TESTS_STUDY_VARIANTS_H_

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"

namespace vox {

class AnyTracer {
 public:
  virtual ~AnyTracer() = default;
  virtual StatusOr<std::optional<Hit>> FirstHit(const Ray& ray, TraceCounters* c) const = 0;
  virtual int n1() const = 0;
  virtual int n2() const = 0;
};

struct TraversalVariant {
  std::string name;    // e.g. "fixed64/39 long-double", "aw double"
  std::string family;  // "word", "frac", "transition", "amanatides-woo"
  int word_bits = 0;   // 0 for Amanatides-Woo
  int frac_bits = 0;
  std::string real;    // set-up and transition arithmetic: float, double, long-double, exact
  // Largest step (levels) the variant can trace; Create refuses more.
  int max_step_levels = 20;
  std::function<StatusOr<std::unique_ptr<AnyTracer>>(const OctreeView&, int n1)> create;
};

// Every variant of the study, the default (fixed64/39 long-double) first.
std::vector<TraversalVariant> TraversalVariants();

}  // namespace vox

#endif  // VOX_TESTS_STUDY_VARIANTS_H_

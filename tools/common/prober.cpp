#include "tools/common/prober.h"

#include <climits>
#include <cmath>
#include <variant>

#include "core/ray.h"
#include "core/shapes.h"
#include "render/camera.h"
#include "render/lod.h"
#include "storage/lod.h"
#include "core/util/memory_budget.h"
#include "storage/store.h"
#include "storage/store_budget.h"

namespace vox {

namespace {
// Creates a T into alternative kIndex of `out`.
template <size_t kIndex, class T, class Variant>
Status EmplaceTracer(const OctreeView& view, int n1, Variant* out) {
  auto tr = T::Create(view, n1);
  if (!tr.ok()) return tr.status();
  out->template emplace<kIndex>(std::move(tr).value());
  return OkStatus();
}
}  // namespace

struct Prober::Impl {
  std::unique_ptr<MemoryOctree> memory;
  std::unique_ptr<Store> owned;
  Store* store = nullptr;  // `owned`, or OpenOn's
  glm::i64vec3 origin{0};
  // --fixed 128, 64, auto; with --tracer long-double, then render (double).
  std::variant<Tracer<Fixed128, long double>, DefaultTracer, AutoTracer<long double>,
               Tracer<Fixed128, double>, Tracer<Fixed64, double>, AutoTracer<double>>
      tracer;
  // --lod
  std::unique_ptr<LodPyramid> pyramid;
  std::optional<LodTracer> lod;
  std::optional<LodLevelTracer> lod_base;
  double cone_rad = 0, cone_width = 0;
};

Prober::Prober(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Prober::~Prober() = default;

Status CheckProbeOptions(const ProbeOptions& opt) {
  if (opt.fixed != 0 && opt.fixed != 64 && opt.fixed != 128)
    return InvalidArgumentError("--fixed takes auto, 64 or 128");
  if ((opt.cone_rad >= 0 || opt.cone_width > 0) && opt.lod == 0)
    return InvalidArgumentError("--cone-rad and --cone-width need --lod F");
  if (opt.lod > 0 && opt.cone_rad < 0)
    return InvalidArgumentError("--lod needs --cone-rad R (the cone's spread, radians)");
  if (opt.single_step && !opt.split.empty())
    return InvalidArgumentError("--single-step and --split exclude each other");
  return OkStatus();
}

StatusOr<std::unique_ptr<Prober>> Prober::Open(const ProbeOptions& opt) {
  return OpenOn(nullptr, opt);
}

StatusOr<std::unique_ptr<Prober>> Prober::OpenOn(Store* open_store, const ProbeOptions& opt) {
  // Messages as vox-probe prints them: some with the status code, some without.
  auto fail = [](const Status& s, bool with_code) {
    return Status(s.code(), with_code ? s.ToString() : s.message());
  };
  if (open_store == nullptr && opt.generate.empty() == opt.store.empty())
    return InvalidArgumentError("give either --generate SHAPE or a store directory");
  VOX_RETURN_IF_ERROR(CheckProbeOptions(opt));
  if (opt.lod > 0 && opt.store.empty() && open_store == nullptr)
    return InvalidArgumentError("--lod needs a store with a level-of-detail pyramid");
  auto impl = std::make_unique<Impl>();
  OctreeView view;
  if (!opt.generate.empty()) {
    auto vol = GenerateShape(opt.generate);
    if (!vol.ok()) return fail(vol.status(), false);
    const int bl = opt.brick_level >= 0 ? opt.brick_level : std::max(1, vol->levels - 5);
    auto tree = MemoryOctree::Build(std::move(vol->voxels), vol->levels, bl);
    if (!tree.ok()) return fail(tree.status(), false);
    impl->memory = std::move(tree).value();
    view = impl->memory->view();
  } else if (open_store != nullptr) {
    impl->store = open_store;
    view = impl->store->view();
    impl->origin = impl->store->meta().origin;
  } else {
    auto budget = ChooseProcessBudget(opt.memory_bytes);
    if (!budget.ok()) return fail(budget.status(), true);
    OpenOptions oo;
    oo.cache_bytes = opt.cache_mb > 0 ? opt.cache_mb << 20 : budget->bytes;
    auto s = Store::Open(opt.store, oo);
    if (!s.ok()) return fail(s.status(), true);
    impl->owned = std::move(s).value();
    impl->store = impl->owned.get();
    auto split = BudgetReader(impl->store, budget->bytes, uint64_t(opt.cache_mb) << 20);
    if (!split.ok()) return fail(split.status(), true);
    view = impl->store->view();
    impl->origin = impl->store->meta().origin;
  }
  if (opt.lod > 0) {
    OpenOptions oo;
    oo.cache_bytes = opt.cache_mb > 0 ? opt.cache_mb << 20 : size_t(256) << 20;
    auto p = LodPyramid::Open(opt.store, *impl->store, oo);
    if (!p.ok()) return Status(p.status().code(), "--lod: " + p.status().ToString());
    impl->pyramid = std::move(p).value();
    std::vector<Volume*> levels;
    for (int l = 1; l <= impl->pyramid->max_level(); ++l) levels.push_back(impl->pyramid->level(l));
    auto lt = LodTracer::Create(impl->store, levels, opt.lod);
    if (!lt.ok()) return fail(lt.status(), false);
    impl->lod = *lt;
    auto bt = LodLevelTracer::Create(view, DefaultFirstStepLevels(view.levels));
    if (!bt.ok()) return fail(bt.status(), false);
    impl->lod_base = *bt;
    impl->cone_rad = opt.cone_rad;
    impl->cone_width = opt.cone_width;
  }
  int n1 = DefaultFirstStepLevels(view.levels);
  if (opt.single_step) {
    n1 = view.levels;
  } else if (!opt.split.empty()) {
    auto s = ParseSplit(opt.split, view.levels);
    if (!s.ok()) return fail(s.status(), false);
    n1 = *s;
  }
  const bool render = opt.tracer != "long-double";
  Status made;
  if (opt.fixed == 128)
    made = render ? EmplaceTracer<3, Tracer<Fixed128, double>>(view, n1, &impl->tracer)
                  : EmplaceTracer<0, Tracer<Fixed128, long double>>(view, n1, &impl->tracer);
  else if (opt.fixed == 64)
    made = render ? EmplaceTracer<4, Tracer<Fixed64, double>>(view, n1, &impl->tracer)
                  : EmplaceTracer<1, DefaultTracer>(view, n1, &impl->tracer);
  else
    made = render ? EmplaceTracer<5, AutoTracer<double>>(view, n1, &impl->tracer)
                  : EmplaceTracer<2, AutoTracer<long double>>(view, n1, &impl->tracer);
  if (!made.ok()) return fail(made, false);
  // The render tracer's misses first, as vox-render (render/lod.h ClipToOccupiedBox).
  if (render && impl->store != nullptr && impl->store->meta().voxel_count != 0) {
    const StoreMeta& m = impl->store->meta();
    const int64_t lo[3] = {m.bbox_min.x - m.origin.x, m.bbox_min.y - m.origin.y,
                           m.bbox_min.z - m.origin.z};
    const int64_t hi[3] = {m.bbox_max.x - m.origin.x, m.bbox_max.y - m.origin.y,
                           m.bbox_max.z - m.origin.z};
    if (lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2])
      std::visit([&](auto& t) { t.SetOccupiedBox(lo, hi); }, impl->tracer);
  }
  return std::unique_ptr<Prober>(new Prober(std::move(impl)));
}

StatusOr<std::optional<Hit>> Prober::Trace(const Ray& index_ray, TraceCounters* counters) const {
  VOX_RETURN_IF_ERROR(ValidateRay(index_ray));  // refused in the caller's coordinates
  Ray r = index_ray;
  r.origin -= glm::dvec3(impl_->origin);  // index space -> grid space
  auto hit = std::visit([&](const auto& t) { return t.FirstHit(r, counters); }, impl_->tracer);
  if (hit.ok() && *hit) (*hit)->voxel += impl_->origin;
  return hit;
}

bool Prober::lod() const { return impl_->lod.has_value(); }

StatusOr<std::optional<Hit>> Prober::TraceLod(const Ray& index_ray, TraceCounters* counters,
                                              LodCounters* lc, int* level) const {
  *level = 0;
  VOX_RETURN_IF_ERROR(ValidateRay(index_ray));  // refused in the caller's coordinates
  Ray r = index_ray;
  r.origin -= glm::dvec3(impl_->origin);
  const Cone cone{impl_->cone_width, impl_->cone_rad * std::sqrt(glm::dot(r.dir, r.dir))};
  if (impl_->lod->Exact(r, cone)) {
    ++lc->exact_rays;
    auto h = std::visit([&](const auto& t) { return t.FirstHit(r, counters); }, impl_->tracer);
    if (h.ok() && *h) {
      (*h)->voxel += impl_->origin;
      ++lc->stops[0];
    }
    return h;
  }
  LodSegment seg;
  auto f = impl_->lod->FirstHit(*impl_->lod_base, nullptr, r, cone, false, 0.0, &seg, nullptr, counters);
  if (!f.ok()) return f.status();
  if (!*f) return std::optional<Hit>();
  Hit hit = seg.hit;
  hit.t = seg.t0;
  *level = seg.level;
  ++lc->stops[seg.level];
  hit.voxel = (hit.voxel << int64_t(seg.level)) + impl_->origin;
  return std::optional<Hit>(hit);
}

}  // namespace vox

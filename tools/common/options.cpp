#include "tools/common/options.h"

#include <climits>
#include <cmath>
#include <variant>

#include "core/shapes.h"
#include "render/camera.h"
#include "render/lod.h"
#include "storage/lod.h"
#include "storage/memory_budget.h"
#include "storage/store.h"
#include "storage/store_budget.h"
#include "tools/common/flags.h"

namespace vox {
namespace {

bool OneOf(std::string_view flag, std::initializer_list<std::string_view> names) {
  for (std::string_view n : names)
    if (flag == n) return true;
  return false;
}

}  // namespace

FlagArity IngestFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--force", "--quiet", "--no-lod"})) return FlagArity::kSwitch;
  if (OneOf(flag, {"--grid", "--levels", "--isovalue", "--threshold", "--color", "--zstd-level",
                   "--normal-bits", "--threads", "--memory-mb", "--add-lod", "--max-voxels"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyIngestFlag(IngestCommand* c, const std::string& flag, const std::string& v) {
  IngestOptions& o = c->options;
  if (flag == "--force") {
    o.force = true;
  } else if (flag == "--quiet") {
    c->quiet = true;
  } else if (flag == "--no-lod") {
    o.lod = false;
  } else if (flag == "--add-lod") {
    c->add_lod = v;
  } else if (flag == "--max-voxels") {
    double d = 0;
    if (!ParseDouble(v, &d) || !(d >= 1) || d > 1e18 || d != std::floor(d))
      return InvalidArgumentError("--max-voxels " + v + ": must be a whole number of voxels (1e10 is fine)");
    c->limits.max_tile_voxels = uint64_t(d);
  } else if (flag == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o.memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (flag == "--grid") {
    o.grid_name = v;
  } else if (flag == "--levels") {
    o.levels = v;
  } else if (flag == "--color") {
    o.color_grid = v;
  } else if (flag == "--normal-bits") {
    if (!ParseInt(v, 8, 16, &o.normal_bits))
      return InvalidArgumentError("--normal-bits " + v +
                                  ": must be a whole number of bits in 8..16");
  } else if (flag == "--isovalue" || flag == "--threshold") {
    double d;
    if (!ParseDouble(v, &d)) return InvalidArgumentError(flag + " " + v + ": not a finite number");
    (flag == "--isovalue" ? o.isovalue : o.threshold) = d;
  } else if (flag == "--threads" || flag == "--zstd-level") {
    if (!ParseInt(v, -1000000, 1000000, flag == "--threads" ? &o.threads : &o.zstd_level))
      return InvalidArgumentError(flag + " " + v + ": not a whole number");
  } else {
    return InvalidArgumentError("unknown option " + flag);
  }
  return OkStatus();
}

Status CheckIngestCommand(const IngestCommand& c) {
  const IngestOptions& o = c.options;
  if (o.threads < 0 || o.threads > kMaxThreads)
    return InvalidArgumentError("--threads " + std::to_string(o.threads) + ": must be in 1.." +
                                std::to_string(kMaxThreads) + " (or 0 for all cores)");
  if (o.zstd_level < 1 || o.zstd_level > 22)
    return InvalidArgumentError("--zstd-level must be in 1..22");
  if (auto lv = ParseLevels(o.levels); !lv.ok()) return InvalidArgumentError(lv.status().message());
  return OkStatus();
}

FlagArity RenderFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--single-step", "--quiet", "--prefetch", "--no-prefetch", "--float",
                   "--read-windows", "--no-read-windows", "--beam", "--no-beam"}))
    return FlagArity::kSwitch;
  if (OneOf(flag, {"--cam", "--scene", "-o", "--preview", "--split", "--cache-mb", "--memory-mb",
                   "--threads", "--tile-size", "--tiles", "--stats", "--layers", "--size",
                   "--io-threads", "--lod", "--compression"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyRenderFlag(RenderJobOptions* o, const std::string& a, const std::string& v) {
  if (a == "--single-step") {
    o->single_step = true;
  } else if (a == "--quiet") {
    o->quiet = true;
  } else if (a == "--prefetch") {
    o->prefetch = true;
  } else if (a == "--no-prefetch") {  // once accepted and silently the default: refused, saying so
    return InvalidArgumentError("--no-prefetch was removed: bricks are read without prefetching "
                                "unless --prefetch is given");
  } else if (a == "--read-windows" || a == "--no-read-windows") {
    o->read_windows = a == "--read-windows";
  } else if (a == "--beam" || a == "--no-beam") {
    o->beam = a == "--beam";
  } else if (a == "--lod") {
    VOX_ASSIGN_OR_RETURN(o->lod, ParseLodFactor("--lod", v));
  } else if (a == "--float") {
    o->layers.float_color = true;
  } else if (a == "--compression") {
    VOX_ASSIGN_OR_RETURN(o->compression, ParseExrCompression(v));
  } else if (a == "--io-threads") {
    if (!ParseInt(v, 1, kMaxIoThreads, &o->io_threads))
      return InvalidArgumentError("--io-threads '" + v + "': expected 1.." + std::to_string(kMaxIoThreads));
  } else if (a == "--cam") {
    o->camera_path = v;
  } else if (a == "--scene") {
    o->scene_path = v;
  } else if (a == "-o") {
    o->exr_path = v;
  } else if (a == "--preview") {
    o->preview_path = v;
  } else if (a == "--split") {
    o->split = v;
  } else if (a == "--stats") {
    o->stats_path = v;
  } else if (a == "--cache-mb") {
    int mb = 0;
    if (!ParseInt(v, 1, 1 << 22, &mb))
      return InvalidArgumentError("--cache-mb '" + v + "': expected a positive integer");
    o->cache_mb = size_t(mb);
  } else if (a == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o->memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (a == "--threads") {
    if (!ParseInt(v, 0, kMaxThreads, &o->threads))
      return InvalidArgumentError("--threads '" + v + "': expected 0.." + std::to_string(kMaxThreads));
  } else if (a == "--tile-size") {
    if (!ParseInt(v, INT_MIN, INT_MAX, &o->tile_size))
      return InvalidArgumentError("--tile-size '" + v + "': expected an integer");
  } else if (a == "--tiles") {
    VOX_ASSIGN_OR_RETURN(o->part, ParsePartSpec(v));
  } else if (a == "--layers") {
    for (const std::string& item : SplitList(v)) {
      if (item == "normal")
        o->layers.normal = true;
      else if (item == "voxel")
        o->layers.voxel = true;
      else
        return InvalidArgumentError("--layers: unknown layer '" + item + "' (normal, voxel)");
    }
  } else if (a == "--size") {
    const size_t x = v.find('x');
    if (x == std::string::npos || !ParseInt(v.substr(0, x), 1, kMaxImageSide, &o->default_width) ||
        !ParseInt(v.substr(x + 1), 1, kMaxImageSide, &o->default_height))
      return InvalidArgumentError("--size '" + v + "': expected WxH");
  } else {
    return InvalidArgumentError("unknown flag " + a);
  }
  return OkStatus();
}

FlagArity ProbeFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--single-step", "--stats"})) return FlagArity::kSwitch;
  if (OneOf(flag, {"--generate", "--split", "--memory-mb", "--brick-level", "--cache-mb",
                   "--fixed", "--tracer", "--lod", "--cone-rad", "--cone-width"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyProbeFlag(ProbeOptions* o, const std::string& a, const std::string& v) {
  if (a == "--single-step") {
    o->single_step = true;
  } else if (a == "--stats") {
    o->stats = true;
  } else if (a == "--generate") {
    o->generate = v;
  } else if (a == "--tracer") {
    if (v != "render" && v != "long-double")
      return InvalidArgumentError("--tracer '" + v + "': expected render or long-double");
    o->tracer = v;
  } else if (a == "--split") {
    o->split = v;
  } else if (a == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o->memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (a == "--lod") {
    VOX_ASSIGN_OR_RETURN(o->lod, ParseLodFactor(a, v));
  } else if (a == "--cone-rad" || a == "--cone-width") {
    double d = 0;
    if (!ParseDouble(v, &d) || d < 0)
      return InvalidArgumentError(a + " '" + v + "': expected a finite number >= 0");
    (a == "--cone-rad" ? o->cone_rad : o->cone_width) = d;
  } else if (a == "--brick-level" || a == "--cache-mb" || a == "--fixed") {
    int64_t n = 0;
    if (a == "--fixed" && v == "auto") {
      o->fixed = 0;
    } else if (!ParseInt(v, 0, a == "--cache-mb" ? INT64_MAX >> 20 : INT32_MAX, &n)) {
      return InvalidArgumentError(a + ": '" + v + "' is not a non-negative integer");
    } else if (a == "--brick-level") {
      o->brick_level = int(n);
    } else if (a == "--cache-mb") {
      o->cache_mb = size_t(n);
    } else {
      o->fixed = int(n);
    }
  } else {
    return InvalidArgumentError("unknown option " + a);
  }
  return OkStatus();
}

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
  std::unique_ptr<Store> store;
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

StatusOr<std::unique_ptr<Prober>> Prober::Open(const ProbeOptions& opt) {
  // Messages as vox-probe prints them: some with the status code, some without.
  auto fail = [](const Status& s, bool with_code) {
    return Status(s.code(), with_code ? s.ToString() : s.message());
  };
  if (opt.generate.empty() == opt.store.empty())
    return InvalidArgumentError("give either --generate SHAPE or a store directory");
  if (opt.fixed != 0 && opt.fixed != 64 && opt.fixed != 128)
    return InvalidArgumentError("--fixed takes auto, 64 or 128");
  if ((opt.cone_rad >= 0 || opt.cone_width > 0) && opt.lod == 0)
    return InvalidArgumentError("--cone-rad and --cone-width need --lod F");
  if (opt.lod > 0) {
    if (opt.store.empty()) return InvalidArgumentError("--lod needs a store with a level-of-detail pyramid");
    if (opt.cone_rad < 0) return InvalidArgumentError("--lod needs --cone-rad R (the cone's spread, radians)");
  }
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
  } else {
    auto budget = ChooseProcessBudget(opt.memory_bytes);
    if (!budget.ok()) return fail(budget.status(), true);
    OpenOptions oo;
    oo.cache_bytes = opt.cache_mb > 0 ? opt.cache_mb << 20 : budget->bytes;
    auto s = Store::Open(opt.store, oo);
    if (!s.ok()) return fail(s.status(), true);
    impl->store = std::move(s).value();
    auto split = BudgetReader(impl->store.get(), budget->bytes, uint64_t(opt.cache_mb) << 20);
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
    auto lt = LodTracer::Create(impl->store.get(), levels, opt.lod);
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
    if (!opt.split.empty())
      return InvalidArgumentError("--single-step and --split exclude each other");
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

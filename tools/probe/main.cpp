// vox-probe: first hits of rays read from stdin, one "ox oy oz dx dy dz" per
// line (decimal or C99 hex floats, index space: voxel (i,j,k) is
// [i,i+1)x[j,j+1)x[k,k+1)); prints "hit i j k t" or "miss" per line, in order.
//
//   vox-probe --generate sphere:1024 [--brick-level L] [options] < rays.txt
//   vox-probe store/ [options] < rays.txt
// Options: --split N1+N2|N1, --single-step, --memory-mb M, --cache-mb M, --stats,
//   --fixed auto|64|128 (fixed-point word; auto: 64 up to 2^26 grids, else 128),
//   --lod F --cone-rad R [--cone-width W]: level of detail over the store's
//   pyramid (render/lod.h) with a cone per ray of width W + R * t |dir|
//   voxels at ray parameter t; a stop at a coarse cell of level L prints
//   "lod L i j k t" (i j k: the cell's first voxel), a voxel "hit i j k t".
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <memory>
#include <new>
#include <optional>
#include <string>

#include "core/core.h"
#include "core/ray_text.h"
#include "core/shapes.h"
#include "render/lod.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_budget.h"
#include "tools/common/flags.h"

namespace {

constexpr const char* kUsage =
    "usage: vox-probe (--generate SHAPE | STORE_DIR) [--split N1+N2|N1] [--single-step]\n"
    "                 [--brick-level L] [--memory-mb M] [--cache-mb M] [--fixed auto|64|128]\n"
    "                 [--stats] [--lod F --cone-rad R [--cone-width W]] < rays.txt\n"
    "  --lod F: stop at the first occupied cell of the store's level-of-detail pyramid whose\n"
    "  size is at most F times the ray's cone width (W + R t |dir| voxels at t); prints\n"
    "  'lod L i j k t' for a cell of level L > 0\n"
    "  --memory-mb: memory the process may use, in MiB (or 2G); default: the memory\n"
    "  cgroup's limit, or 3/4 of MemAvailable. --cache-mb: the brick cache inside it\n"
    "  (default: what the budget leaves)\n"
    "  SHAPE: sphere:N, torus:N, cubes:N, noise:N (N voxels per axis), corner:L (2^L grid)\n";

struct Options {
  std::string generate, store, split;
  bool single_step = false, stats = false;
  int brick_level = -1;
  size_t cache_mb = 0;        // 0: from the memory budget
  uint64_t memory_bytes = 0;  // 0: detected
  int fixed = 0;  // 0: auto
  double lod = 0.0;                 // --lod F; 0: off
  double cone_rad = -1.0, cone_width = 0.0;
};

int Fail(const std::string& msg) {
  std::fprintf(stderr, "vox-probe: %s\n", msg.c_str());
  return 2;
}

template <class TracerT>
int Run(const TracerT& tracer, const glm::i64vec3& origin, bool stats) {
  vox::TraceCounters counters;
  std::string line;
  long lineno = 0;
  int bad = 0;
  const glm::dvec3 shift(origin);
  while (std::getline(std::cin, line)) {
    ++lineno;
    auto ray = vox::ParseRayLine(line);
    vox::Status st = ray.status();
    std::optional<vox::Hit> hit;
    if (st.ok()) {
      vox::Ray r = *ray;
      r.origin -= shift;  // index space -> grid space
      auto h = tracer.FirstHit(r, &counters);
      st = h.status();
      if (st.ok()) hit = *h;
    }
    if (!st.ok()) {
      std::fprintf(stderr, "vox-probe: stdin line %ld: %s: %s\n", lineno, st.message().c_str(),
                   line.c_str());
      std::puts("error");
      ++bad;
      continue;
    }
    if (hit) {
      glm::i64vec3 v = hit->voxel + origin;
      std::puts(vox::FormatHitLine(&v, hit->t).c_str());
    } else {
      std::puts("miss");
    }
  }
  if (stats) std::fprintf(stderr, "vox-probe: %s\n", counters.ToString().c_str());
  if (bad) std::fprintf(stderr, "vox-probe: %d of %ld lines refused\n", bad, lineno);
  return bad ? 1 : 0;
}

// --lod: each ray's first stop over the pyramid; rays the cone keeps at
// level 0 go to `exact`, the probe's usual tracer, so they answer as without --lod.
template <class TracerT>
int RunLod(const TracerT& exact, const vox::LodTracer& lod, const vox::LodLevelTracer& base,
           const glm::i64vec3& origin, const Options& opt) {
  vox::TraceCounters counters;
  vox::LodCounters lc;
  std::string line;
  long lineno = 0;
  int bad = 0;
  const glm::dvec3 shift(origin);
  while (std::getline(std::cin, line)) {
    ++lineno;
    auto ray = vox::ParseRayLine(line);
    vox::Status st = ray.status();
    std::optional<vox::Hit> hit;
    int level = 0;
    if (st.ok()) {
      vox::Ray r = *ray;
      r.origin -= shift;
      const vox::Cone cone{opt.cone_width, opt.cone_rad * std::sqrt(glm::dot(r.dir, r.dir))};
      if (lod.Exact(r, cone)) {
        ++lc.exact_rays;
        auto h = exact.FirstHit(r, &counters);
        st = h.status();
        if (st.ok()) hit = *h;
      } else {
        vox::LodSegment seg;
        auto f = lod.FirstHit(base, r, cone, false, 0.0, &seg, nullptr, &counters);
        st = f.status();
        if (st.ok() && *f) {
          hit = seg.hit;
          hit->t = seg.t0;
          level = seg.level;
        }
      }
    }
    if (!st.ok()) {
      std::fprintf(stderr, "vox-probe: stdin line %ld: %s: %s\n", lineno, st.message().c_str(),
                   line.c_str());
      std::puts("error");
      ++bad;
      continue;
    }
    if (!hit) {
      std::puts("miss");
      continue;
    }
    ++lc.stops[level];
    glm::i64vec3 v = (hit->voxel << int64_t(level)) + origin;
    if (level == 0)
      std::puts(vox::FormatHitLine(&v, hit->t).c_str());
    else
      std::printf("lod %d %s\n", level, vox::FormatHitLine(&v, hit->t).substr(4).c_str());
  }
  if (opt.stats) {
    std::fprintf(stderr, "vox-probe: %s\n", counters.ToString().c_str());
    std::fprintf(stderr, "vox-probe: lod stops by level:");
    for (int l = 0; l <= vox::kMaxLevels; ++l)
      if (lc.stops[l] > 0) std::fprintf(stderr, " %d:%llu", l, (unsigned long long)lc.stops[l]);
    std::fprintf(stderr, " (exact rays %llu)\n", (unsigned long long)lc.exact_rays);
  }
  if (bad) std::fprintf(stderr, "vox-probe: %d of %ld lines refused\n", bad, lineno);
  return bad ? 1 : 0;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  Options opt;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    std::optional<std::string> v;
    if (flags.IsHelp()) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--generate") {
      if (!(v = flags.Value())) return Fail("--generate needs a shape\n" + std::string(kUsage));
      opt.generate = *v;
    } else if (a == "--split") {
      if (!(v = flags.Value())) return Fail("--split needs N1+N2 or N1");
      opt.split = *v;
    } else if (a == "--single-step") {
      opt.single_step = true;
    } else if (a == "--stats") {
      opt.stats = true;
    } else if (a == "--memory-mb") {
      if (!(v = flags.Value())) return Fail("--memory-mb needs a size");
      auto bytes = vox::ParseMemorySize("--memory-mb", *v);
      if (!bytes.ok()) return Fail(bytes.status().message());
      opt.memory_bytes = *bytes;
    } else if (a == "--lod" || a == "--cone-rad" || a == "--cone-width") {
      if (!(v = flags.Value())) return Fail(a + " needs a number");
      auto f = vox::ParseLodFactor(a, *v);
      if (a == "--lod") {
        if (!f.ok()) return Fail(f.status().message());
        opt.lod = *f;
      } else {
        double d = 0;
        if (!vox::ParseDouble(*v, &d) || d < 0)
          return Fail(a + " '" + *v + "': expected a finite number >= 0");
        (a == "--cone-rad" ? opt.cone_rad : opt.cone_width) = d;
      }
    } else if (a == "--brick-level" || a == "--cache-mb" || a == "--fixed") {
      if (!(v = flags.Value())) return Fail(a + " needs a number");
      int64_t n = 0;
      if (a == "--fixed" && *v == "auto") {
        opt.fixed = 0;
      } else if (!vox::ParseInt(*v, 0, a == "--cache-mb" ? INT64_MAX >> 20 : INT32_MAX, &n)) {
        return Fail(a + ": '" + *v + "' is not a non-negative integer");
      } else if (a == "--brick-level") {
        opt.brick_level = int(n);
      } else if (a == "--cache-mb") {
        opt.cache_mb = size_t(n);
      } else {
        opt.fixed = int(n);
      }
    } else if (flags.IsFlag()) {
      return Fail("unknown option " + a + "\n" + kUsage);
    } else if (opt.store.empty()) {
      opt.store = a;
    } else {
      return Fail("more than one store given\n" + std::string(kUsage));
    }
  }
  if (opt.generate.empty() == opt.store.empty())
    return Fail("give either --generate SHAPE or a store directory\n" + std::string(kUsage));
  if (opt.fixed != 0 && opt.fixed != 64 && opt.fixed != 128)
    return Fail("--fixed takes auto, 64 or 128");
  if ((opt.cone_rad >= 0 || opt.cone_width > 0) && opt.lod == 0)
    return Fail("--cone-rad and --cone-width need --lod F");
  if (opt.lod > 0) {
    if (opt.store.empty()) return Fail("--lod needs a store with a level-of-detail pyramid");
    if (opt.cone_rad < 0) return Fail("--lod needs --cone-rad R (the cone's spread, radians)");
  }

  std::unique_ptr<vox::MemoryOctree> memory;
  std::unique_ptr<vox::Store> store;
  vox::OctreeView view;
  glm::i64vec3 origin(0);
  if (!opt.generate.empty()) {
    auto vol = vox::GenerateShape(opt.generate);
    if (!vol.ok()) return Fail(vol.status().message());
    int bl = opt.brick_level >= 0 ? opt.brick_level : std::max(1, vol->levels - 5);
    auto tree = vox::MemoryOctree::Build(std::move(vol->voxels), vol->levels, bl);
    if (!tree.ok()) return Fail(tree.status().message());
    memory = std::move(tree).value();
    view = memory->view();
  } else {
    auto budget = vox::ChooseProcessBudget(opt.memory_bytes);
    if (!budget.ok()) return Fail(budget.status().ToString());
    vox::OpenOptions oo;
    oo.cache_bytes = opt.cache_mb > 0 ? opt.cache_mb << 20 : budget->bytes;
    auto s = vox::Store::Open(opt.store, oo);
    if (!s.ok()) return Fail(s.status().ToString());
    store = std::move(s).value();
    auto split = vox::BudgetReader(store.get(), budget->bytes, uint64_t(opt.cache_mb) << 20);
    if (!split.ok()) return Fail(split.status().ToString());
    view = store->view();
    origin = store->meta().origin;
  }
  std::unique_ptr<vox::LodPyramid> pyramid;
  std::optional<vox::LodTracer> lod;
  std::optional<vox::LodLevelTracer> lod_base;
  if (opt.lod > 0) {
    vox::OpenOptions oo;
    oo.cache_bytes = opt.cache_mb > 0 ? opt.cache_mb << 20 : size_t(256) << 20;
    auto p = vox::LodPyramid::Open(opt.store, *store, oo);
    if (!p.ok()) return Fail("--lod: " + p.status().ToString());
    pyramid = std::move(p).value();
    std::vector<vox::Volume*> levels;
    for (int l = 1; l <= pyramid->max_level(); ++l) levels.push_back(pyramid->level(l));
    auto lt = vox::LodTracer::Create(store.get(), levels, opt.lod);
    if (!lt.ok()) return Fail(lt.status().message());
    lod = *lt;
    auto bt = vox::LodLevelTracer::Create(view, vox::DefaultFirstStepLevels(view.levels));
    if (!bt.ok()) return Fail(bt.status().message());
    lod_base = *bt;
  }
  int n1 = vox::DefaultFirstStepLevels(view.levels);
  if (opt.single_step) {
    n1 = view.levels;
    if (!opt.split.empty()) return Fail("--single-step and --split exclude each other");
  } else if (!opt.split.empty()) {
    auto s = vox::ParseSplit(opt.split, view.levels);
    if (!s.ok()) return Fail(s.status().message());
    n1 = *s;
  }
  if (opt.fixed == 128) {
    auto tr = vox::Tracer<vox::Fixed128, long double>::Create(view, n1);
    if (!tr.ok()) return Fail(tr.status().message());
    if (lod) return RunLod(*tr, *lod, *lod_base, origin, opt);
    return Run(*tr, origin, opt.stats);
  }
  if (opt.fixed == 64) {
    auto tr = vox::DefaultTracer::Create(view, n1);
    if (!tr.ok()) return Fail(tr.status().message());
    if (lod) return RunLod(*tr, *lod, *lod_base, origin, opt);
    return Run(*tr, origin, opt.stats);
  }
  auto tr = vox::AutoTracer<long double>::Create(view, n1);
  if (!tr.ok()) return Fail(tr.status().message());
  if (lod) return RunLod(*tr, *lod, *lod_base, origin, opt);
  return Run(*tr, origin, opt.stats);
}

// Allocation failures anywhere (an image, a brick, a table sized from input)
// end with a clear message and exit 1, never an abort.
int main(int argc, char** argv) {
  try {
    return RunTool(argc, argv);
  } catch (const std::bad_alloc&) {
    fprintf(stderr, "vox-probe: out of memory (std::bad_alloc); try smaller sizes or budgets\n");
    return 1;
  }
}

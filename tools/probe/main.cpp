// vox-probe: first hits of rays read from stdin, one "ox oy oz dx dy dz" per
// line (decimal or C99 hex floats, index space: voxel (i,j,k) is
// [i,i+1)x[j,j+1)x[k,k+1)); prints "hit i j k t" or "miss" per line, in order.
//
//   vox-probe --generate sphere:1024 [--brick-level L] [options] < rays.txt
//   vox-probe store/ [options] < rays.txt
// Options: --split N1+N2|N1, --single-step, --memory-mb M, --cache-mb M, --stats,
//   --tracer render|long-double (render, the default: the tracer vox-render
//   traces with, AutoTracer<double> with the store's occupied box, so the
//   probe's answers are the render's; long-double: a long-double set-up, the
//   arithmetic of DefaultTracer; docs/accuracy.md has how they differ),
//   --fixed auto|64|128 (fixed-point word; auto: 64 up to 2^26 grids, else 128),
//   --lod F --cone-rad R [--cone-width W]: level of detail over the store's
//   pyramid (render/lod.h) with a cone per ray of width W + R * t |dir|
//   voxels at ray parameter t; a stop at a coarse cell of level L prints
//   "lod L i j k t" (i j k: the cell's first voxel), a voxel "hit i j k t".
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "core/core.h"
#include "core/ray_text.h"
#include "tools/common/flags.h"
#include "tools/common/options.h"
#include "tools/common/prober.h"
#include "tools/common/tool_main.h"

namespace {

constexpr const char* kUsage =
    "usage: vox-probe (--generate SHAPE | STORE_DIR) [--split N1+N2|N1] [--single-step]\n"
    "                 [--brick-level L] [--memory-mb M] [--cache-mb M] [--fixed auto|64|128]\n"
    "                 [--tracer render|long-double] [--stats] [--lod F --cone-rad R [--cone-width W]]\n"
    "                 < rays.txt\n"
    "  --tracer: render (default) answers as vox-render traces (double set-up, the store's\n"
    "  occupied box); long-double with a long-double set-up (docs/accuracy.md)\n"
    "  --lod F: stop at the first occupied cell of the store's level-of-detail pyramid whose\n"
    "  size is at most F times the ray's cone width (W + R t |dir| voxels at t); prints\n"
    "  'lod L i j k t' for a cell of level L > 0\n"
    "  --memory-mb: memory the process may use, in MiB (or 2G); default: the memory\n"
    "  cgroup's limit, or 3/4 of MemAvailable. --cache-mb: the brick cache inside it\n"
    "  (default: what the budget leaves)\n"
    "  SHAPE: sphere:N, torus:N, cubes:N, noise:N (N voxels per axis), corner:L (2^L grid)\n";


int Fail(const std::string& msg) {
  std::fprintf(stderr, "vox-probe: %s\n", msg.c_str());
  return 2;
}

int Run(const vox::Prober& prober, bool stats) {
  vox::TraceCounters counters;
  vox::LodCounters lc;
  std::string line;
  long lineno = 0;
  int bad = 0;
  while (std::getline(std::cin, line)) {
    ++lineno;
    auto ray = vox::ParseRayLine(line);
    vox::Status st = ray.status();
    std::optional<vox::Hit> hit;
    int level = 0;
    if (st.ok()) {
      auto h = prober.lod() ? prober.TraceLod(*ray, &counters, &lc, &level) : prober.Trace(*ray, &counters);
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
    if (!hit) {
      std::puts("miss");
    } else if (level == 0) {
      std::puts(vox::FormatHitLine(&hit->voxel, hit->t).c_str());
    } else {  // a stop at a coarse cell: "lod L i j k t"
      std::printf("lod %d %s\n", level, vox::FormatHitLine(&hit->voxel, hit->t).substr(4).c_str());
    }
  }
  if (stats) {
    std::fprintf(stderr, "vox-probe: %s\n", counters.ToString().c_str());
    if (prober.lod()) {
      std::fprintf(stderr, "vox-probe: lod stops by level:");
      for (int l = 0; l <= vox::kMaxLevels; ++l)
        if (lc.stops[l] > 0) std::fprintf(stderr, " %d:%llu", l, (unsigned long long)lc.stops[l]);
      std::fprintf(stderr, " (exact rays %llu)\n", (unsigned long long)lc.exact_rays);
    }
  }
  if (bad) std::fprintf(stderr, "vox-probe: %d of %ld lines refused\n", bad, lineno);
  return bad ? 1 : 0;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  vox::ProbeOptions opt;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (flags.IsFlag()) {
      const vox::FlagArity arity = vox::ProbeFlagArity(a);
      if (arity == vox::FlagArity::kUnknown) return Fail("unknown option " + a + "\n" + kUsage);
      std::optional<std::string> v;
      if (arity == vox::FlagArity::kValue && !(v = flags.Value())) {
        if (a == "--generate") return Fail("--generate needs a shape\n" + std::string(kUsage));
        if (a == "--split") return Fail("--split needs N1+N2 or N1");
        if (a == "--memory-mb") return Fail("--memory-mb needs a size");
        return Fail(a + " needs a number");
      }
      vox::Status s = vox::ApplyProbeFlag(&opt, a, v.value_or(""));
      if (!s.ok()) return Fail(s.message());
    } else if (opt.store.empty()) {
      opt.store = a;
    } else {
      return Fail("more than one store given\n" + std::string(kUsage));
    }
  }
  if (opt.generate.empty() == opt.store.empty())
    return Fail("give either --generate SHAPE or a store directory\n" + std::string(kUsage));
  auto prober = vox::Prober::Open(opt);
  if (!prober.ok()) return Fail(prober.status().message());
  return Run(**prober, opt.stats);
}

int main(int argc, char** argv) { return vox::ToolMain("vox-probe", argc, argv, RunTool); }

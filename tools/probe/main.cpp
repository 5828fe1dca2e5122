// vox-probe: first hits of rays read from stdin, one "ox oy oz dx dy dz" per
// line (decimal or C99 hex floats, vox index space: voxel (i,j,k), OpenVDB's
// Coord(i,j,k), is [i,i+1)x[j,j+1)x[k,k+1), so an OpenVDB index point q is
// q + 0.5 here; docs/usage.md, Spaces); prints "hit i j k t" or "miss" per
// line, in order.
//
//   vox-probe --generate sphere:1024 [--brick-level L] [options] < rays.txt
//   vox-probe store/ [options] < rays.txt
// The options are tools/common/options.h's probe table (vox-probe --help).
// --tracer render, the default, traces as vox-render does (AutoTracer<double>
// with the store's occupied box), so the probe's answers are the render's;
// long-double has DefaultTracer's arithmetic (docs/accuracy.md). With --lod F
// --cone-rad R [--cone-width W] a ray's cone is W + R * t |dir| voxels wide at
// ray parameter t; a stop at a coarse cell of level L prints "lod L i j k t"
// (i j k: the cell's first voxel), a voxel "hit i j k t".
// With --at X Y Z or --slice AXIS INDEX it reads values instead (values.h).
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/core.h"
#include "core/ray_text.h"
#include "tools/common/cli.h"
#include "tools/common/options.h"
#include "tools/common/prober.h"
#include "tools/common/tool_main.h"
#include "tools/probe/values.h"

namespace {

const vox::CommandLineSpec kCommandLine{
    "vox-probe",
    "vox-probe (--generate SHAPE | STORE_DIR) [options] < rays.txt\n"
    "       vox-probe STORE_DIR --at X Y Z [--at ...] | --slice AXIS INDEX -o OUT.exr (vox-probe --at: "
    "its own help)",
    "Traces the rays read from stdin, one 'ox oy oz dx dy dz' per line (decimal or C99 hex "
    "floats, index space: voxel i j k is [i, i+1) x [j, j+1) x [k, k+1), an OpenVDB index point "
    "plus 0.5), through a store or a generated shape, and prints 'hit i j k t' or "
    "'miss' per line, in order.",
    vox::ProbeOptionTable(),
    "Exit codes: 0 done, 1 the store cannot be read (or serve the options) or some lines were\n"
    "refused (each prints 'error'), 2 bad command line (a --generate shape included).\n"};

int UsageError(const std::string& message) {
  return vox::UsageError(kCommandLine.program, message);
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
  if (vox::WantsValues(argc, argv)) return vox::RunValues(argc, argv);  // --at, --slice
  vox::ProbeOptions opt;
  std::vector<std::string> stores;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return vox::ApplyProbeFlag(&opt, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &stores))
    return *exit_code;
  if (stores.size() > 1) return UsageError("more than one store given");
  if (!stores.empty()) opt.store = stores[0];
  if (opt.generate.empty() == opt.store.empty())
    return UsageError("give either --generate SHAPE or a store directory");
  if (vox::Status s = vox::CheckProbeOptions(opt); !s.ok()) return UsageError(s.message());
  auto prober = vox::Prober::Open(opt);
  if (!prober.ok()) {
    std::fprintf(stderr, "vox-probe: %s\n", prober.status().message().c_str());
    // A store that cannot be opened, or cannot serve the options (--lod
    // without a pyramid, a --split past its levels), fails as in every tool
    // (1); a --generate shape that cannot be made is a bad command line (2).
    return opt.generate.empty() ? 1 : 2;
  }
  return Run(**prober, opt.stats);
}

int main(int argc, char** argv) { return vox::ToolMain("vox-probe", argc, argv, RunTool); }

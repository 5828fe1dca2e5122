// vox-gen: writes a procedural level-set shape as a vox store, brick by brick,
// in memory independent of the store's size (tools/gen/generate.h).
//   vox-gen SHAPE store/ --size N [--levels N1+N2|auto] [--band W] [--threads T]
//           [--zstd-level L] [--normal-bits B] [--no-lod] [--force] [--quiet]
// Exit codes: 0 done, 1 the generation failed or was interrupted, 2 bad command line.
#include <signal.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "tools/common/flags.h"
#include "tools/common/tool_main.h"
#include "tools/gen/generate.h"
#include "tools/gen/shapes.h"

namespace {

constexpr char kUsage[] =
    "usage: vox-gen SHAPE store/ --size N [--levels N1+N2|auto] [--band W] [--threads T]\n"
    "               [--zstd-level L] [--normal-bits B] [--no-lod] [--force] [--quiet]\n"
    "  SHAPE            sphere: a level-set sphere shell (like vdb_tool -sphere)\n"
    "                   bumpy: that sphere displaced by fixed multi-octave noise (fine detail)\n"
    "                   rough: the sphere's voxels with jittered normals and speckled colours\n"
    "                   (~10 B/voxel on disk against the sphere's 1: big stores, fast)\n"
    "                   Both are the unit sphere, 15/16 of the grid across, centred on index 0\n"
    "                   (world about [-1,1]^3, voxel size 32/(15 N)); occupied voxels are those\n"
    "                   whose centre's signed distance d (voxels) has -W < d <= 0, with normals.\n"
    "  --size N         voxels per axis: a power of two, 2..1048576 (2^20)\n"
    "  --levels         auto (32^3 bricks) or N1+N2 with N1 + N2 = log2(N), N2 <= 10\n"
    "  --band W         narrow-band half-width in voxels (default 3, like vdb_tool's width)\n"
    "  --threads T      worker threads (default: all cores)\n"
    "  --zstd-level L   brick compression level, 1..22 (default 3)\n"
    "  --normal-bits B  bits per octahedral normal component, 8..16 (default 16)\n"
    "  --no-lod         skip the level-of-detail pyramid (store/lod/, for vox-render --lod)\n"
    "  --force          replace an existing store\n"
    "  --quiet          no progress output\n";

std::atomic<bool> g_cancel{false};
extern "C" void OnSignal(int) { g_cancel.store(true); }

int UsageError(const std::string& message) {
  std::fprintf(stderr, "vox-gen: %s\n%s", message.c_str(), kUsage);
  return 2;
}

bool ParseInt(const std::string& s, long long lo, long long hi, long long* out) {
  errno = 0;
  char* end = nullptr;
  long long v = std::strtoll(s.c_str(), &end, 10);
  if (s.empty() || *end != '\0' || errno != 0 || v < lo || v > hi) return false;
  *out = v;
  return true;
}

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

static int RunTool(int argc, char** argv) {
  vox::gen::GenerateOptions o;
  bool quiet = false, have_size = false;
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--force") {
      o.force = true;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (a == "--no-lod") {
      o.lod = false;
    } else if (a == "--size" || a == "--levels" || a == "--band" || a == "--threads" ||
               a == "--zstd-level" || a == "--normal-bits") {
      if (i + 1 >= argc) return UsageError(a + " needs a value");
      std::string v = argv[++i];
      long long n = 0;
      if (a == "--levels") {
        o.levels = v;
      } else if (a == "--band") {
        char* end = nullptr;
        errno = 0;
        double d = std::strtod(v.c_str(), &end);
        if (v.empty() || *end != '\0' || errno != 0 || !std::isfinite(d))
          return UsageError("--band " + v + ": not a finite number");
        o.band = d;
      } else if (!ParseInt(v, -1000000000000LL, 1000000000000LL, &n)) {
        return UsageError(a + " " + v + ": not a whole number");
      } else if (a == "--size") {
        if (n < 0) return UsageError("--size " + v + ": must be a power of two from 2 to 2^20");
        o.size = uint64_t(n);
        have_size = true;
      } else if (n < -1000000 || n > 1000000) {
        return UsageError(a + " " + v + ": out of range");
      } else if (a == "--threads") {
        if (n < 0 || n > vox::kMaxThreads)
          return UsageError("--threads " + v + ": must be in 1.." + std::to_string(vox::kMaxThreads) +
                            " (or 0 for all cores)");
        o.threads = int(n);
      } else if (a == "--zstd-level") {
        o.zstd_level = int(n);
      } else {
        o.normal_bits = int(n);
      }
    } else if (a.size() > 1 && a[0] == '-') {
      return UsageError("unknown option " + a);
    } else {
      positional.push_back(a);
    }
  }
  if (positional.size() != 2)
    return UsageError("expected a shape and an output store directory, got " +
                      std::to_string(positional.size()) + " arguments");
  o.shape = positional[0];
  o.output = positional[1];
  if (!have_size) return UsageError("--size is required");
  if (vox::Status s = vox::gen::ValidateOptions(o); !s.ok()) return UsageError(s.message());

  struct sigaction sa = {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGHUP, &sa, nullptr);
  o.cancel = &g_cancel;

  double last = Now();
  auto progress = [&](uint64_t bricks, uint64_t voxels) {
    double now = Now();
    if (now - last < 2.0) return;
    last = now;
    std::fprintf(stderr, "vox-gen: %llu bricks, %llu voxels\n", (unsigned long long)bricks,
                 (unsigned long long)voxels);
  };
  auto stats = quiet ? vox::gen::Generate(o) : vox::gen::Generate(o, progress);
  if (!stats.ok()) {
    std::fprintf(stderr, "vox-gen: %s\n", stats.status().ToString().c_str());
    return 1;
  }
  if (!quiet) {
    const vox::gen::GenerateStats& s = *stats;
    std::fprintf(stderr,
                 "wrote %s: %s %llu^3, %llu occupied voxels in %llu bricks (levels %d+%d; %llu "
                 "candidate bricks) in %.2f s (%.2f M voxels/s, %d threads; bricks %.2f s, "
                 "finish %.2f s; level of detail %d levels, %.2f s)\n",
                 o.output.c_str(), o.shape.c_str(), (unsigned long long)o.size,
                 (unsigned long long)s.voxels, (unsigned long long)s.bricks, s.meta.brick_level,
                 s.meta.levels - s.meta.brick_level, (unsigned long long)s.candidate_bricks,
                 s.seconds_total, s.seconds_total > 0 ? double(s.voxels) / s.seconds_total / 1e6 : 0,
                 s.threads, s.seconds_bricks, s.seconds_finish, s.lod_levels, s.seconds_lod);
  }
  return 0;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-gen", argc, argv, RunTool); }

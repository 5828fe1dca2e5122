// vox-ingest: reads an OpenVDB grid and writes a vox store.
//   vox-ingest data.vdb store/ [--grid NAME] [--levels N1+N2|auto] [--isovalue F]
//              [--threshold F] [--color GRID] [--zstd-level L] [--normal-bits B] [--threads N]
//              [--force] [--quiet]
// Exit codes: 0 done, 1 the ingest failed, 2 bad command line.
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ingest/ingest.h"

namespace {

constexpr char kUsage[] =
    "usage: vox-ingest data.vdb store/ [--grid NAME] [--levels N1+N2|auto] [--isovalue F]\n"
    "                  [--threshold F] [--color GRID] [--zstd-level L] [--normal-bits B]\n"
    "                  [--threads N] [--force] [--quiet]\n"
    "  --grid NAME      the grid to ingest (default: the first float or double grid)\n"
    "  --levels         auto (32^3 bricks) or N1+N2: N1 resident levels above bricks of\n"
    "                   N2 levels (2^N2 voxels per axis); each at most 20, N1+N2 at most 40\n"
    "  --isovalue F     level sets: a voxel is occupied when active and value <= F (default 0)\n"
    "  --threshold F    fog volumes: occupied when active and density > F (default 0)\n"
    "  --color GRID     a vec3s/vec3d grid sampled as each voxel's RGB colour\n"
    "  --zstd-level L   brick compression level, 1..22 (default 3)\n"
    "  --normal-bits B  level sets: bits per octahedral normal component, 8..16 (default 16,\n"
    "                   max error 0.004 degrees; 12: 0.06 degrees and a smaller store)\n"
    "  --threads N      worker threads (default: all cores)\n"
    "  --force          replace an existing store\n"
    "  --quiet          no progress output\n";

int UsageError(const std::string& message) {
  std::fprintf(stderr, "vox-ingest: %s\n%s", message.c_str(), kUsage);
  return 2;
}

bool ParseInt(const std::string& s, int* out) {
  errno = 0;
  char* end = nullptr;
  long v = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || *end != '\0' || errno != 0 || v < -1000000 || v > 1000000) return false;
  *out = int(v);
  return true;
}

bool ParseDouble(const std::string& s, double* out) {
  errno = 0;
  char* end = nullptr;
  double v = std::strtod(s.c_str(), &end);
  if (s.empty() || *end != '\0' || errno != 0 || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  vox::IngestOptions o;
  bool quiet = false;
  std::vector<std::string> positional;
  std::string command = "vox-ingest";
  for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
  o.command_line = command;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&](std::string* v) {
      if (i + 1 >= argc) return false;
      *v = argv[++i];
      return true;
    };
    std::string v;
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--force") {
      o.force = true;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (a == "--grid" || a == "--levels" || a == "--isovalue" || a == "--threshold" ||
               a == "--color" || a == "--zstd-level" || a == "--normal-bits" || a == "--threads") {
      if (!value(&v)) return UsageError(a + " needs a value");
      if (a == "--grid") {
        o.grid_name = v;
      } else if (a == "--levels") {
        o.levels = v;
      } else if (a == "--color") {
        o.color_grid = v;
      } else if (a == "--normal-bits") {
        int n;
        if (!ParseInt(v, &n) || n < 8 || n > 16)
          return UsageError("--normal-bits " + v + ": must be a whole number of bits in 8..16");
        o.normal_bits = n;
      } else if (a == "--isovalue" || a == "--threshold") {
        double d;
        if (!ParseDouble(v, &d)) return UsageError(a + " " + v + ": not a finite number");
        (a == "--isovalue" ? o.isovalue : o.threshold) = d;
      } else {
        int n;
        if (!ParseInt(v, &n)) return UsageError(a + " " + v + ": not a whole number");
        (a == "--threads" ? o.threads : o.zstd_level) = n;
      }
    } else if (a.size() > 1 && a[0] == '-') {
      return UsageError("unknown option " + a);
    } else {
      positional.push_back(a);
    }
  }
  if (positional.size() != 2)
    return UsageError("expected an input .vdb file and an output store directory, got " +
                      std::to_string(positional.size()) + " arguments");
  o.input = positional[0];
  o.output = positional[1];
  if (o.threads < 0) return UsageError("--threads must be >= 1 (or 0 for all cores)");
  if (o.zstd_level < 1 || o.zstd_level > 22) return UsageError("--zstd-level must be in 1..22");
  if (auto lv = vox::ParseLevels(o.levels); !lv.ok()) return UsageError(lv.status().message());

  std::unique_ptr<vox::ProgressSink> progress;
  if (!quiet) progress = vox::MakeStderrProgress(isatty(STDERR_FILENO) != 0);
  auto stats = vox::Ingest(o, progress.get());
  if (!stats.ok()) {
    std::fprintf(stderr, "vox-ingest: %s\n", stats.status().ToString().c_str());
    return 1;
  }
  if (!quiet) {
    const vox::IngestStats& s = *stats;
    double rate = s.seconds_total > 0 ? double(s.active_voxels) / s.seconds_total : 0;
    std::fprintf(stderr,
                 "wrote %s: %llu occupied voxels in %llu bricks (levels %d+%d), %llu active "
                 "voxels read in %.2f s (%.1f M active voxels/s, %d threads; open %.2f s, bbox "
                 "%.2f s, bricks %.2f s, finish %.2f s)\n",
                 o.output.c_str(), (unsigned long long)s.occupied_voxels,
                 (unsigned long long)s.bricks, s.meta.brick_level,
                 s.meta.levels - s.meta.brick_level, (unsigned long long)s.active_voxels,
                 s.seconds_total, rate / 1e6, s.threads, s.seconds_open, s.seconds_bbox,
                 s.seconds_bricks, s.seconds_finish);
  }
  return 0;
}

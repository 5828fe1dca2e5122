// vox-gen: writes a procedural level-set shape or fog field as a vox store, brick by brick,
// in memory independent of the store's size (tools/gen/generate.h).
//   vox-gen SHAPE store/ --size N [options]    (kOptions below; vox-gen --help)
// Exit codes: 0 done, 1 the generation failed or was interrupted, 2 bad command line.
#include <signal.h>

#include <atomic>
#include <cstdio>
#include <string>
#include <vector>

#include "core/util/progress.h"
#include "tools/common/cli.h"
#include "tools/common/flags.h"
#include "tools/common/tool_main.h"
#include "tools/gen/generate.h"
#include "tools/gen/shapes.h"

namespace {

constexpr vox::FlagArity kSwitch = vox::FlagArity::kSwitch, kValue = vox::FlagArity::kValue;
constexpr const char* kShapeGroup = "Shape and size";
constexpr const char* kStoreGroup = "Store";
constexpr const char* kRunGroup = "Run";

constexpr vox::OptionSpec kOptions[] = {
    {"--size", kValue, "N", kShapeGroup,
     "voxels per axis: a power of two, 2..1048576 (2^20); required"},
    {"--band", kValue, "W", kShapeGroup,
     "narrow-band half-width in voxels (default 3, like vdb_tool's width)"},
    {"--levels", kValue, "N1+N2|auto", kStoreGroup,
     "auto (32^3 bricks) or N1+N2 with N1 + N2 = log2(N), N2 <= 10"},
    {"--zstd-level", kValue, "L", kStoreGroup, "brick compression level, 1..22 (default 3)"},
    {"--normal-bits", kValue, "B", kStoreGroup,
     "bits per octahedral normal component, 8..16 (default 16)"},
    {"--no-lod", kSwitch, "", kStoreGroup,
     "skip the level-of-detail pyramid (store/lod/, for vox-render --lod)"},
    {"--threads", kValue, "T", kRunGroup, "worker threads (default: all cores)"},
    {"--force", kSwitch, "", kRunGroup, "replace an existing store"},
    {"--quiet", kSwitch, "", kRunGroup, "no progress output"},
};

const vox::CommandLineSpec kCommandLine{
    "vox-gen", "vox-gen SHAPE store/ --size N [options]",
    "Writes a procedural level-set shape or fog field as the vox store store/, brick by brick, "
    "in memory independent of the store's size.",
    kOptions,
    "SHAPE is one of:\n"
    "  sphere  a level-set sphere shell (like vdb_tool -sphere)\n"
    "  bumpy   that sphere displaced by fixed multi-octave noise (fine detail)\n"
    "  rough   the sphere's voxels with jittered normals and speckled colours (~10 B/voxel\n"
    "          on disk against the sphere's 1: big stores, fast)\n"
    "  pair    two spheres of 250 voxels radius half the grid apart, the rest empty (a\n"
    "          sparse volume: --size 2048 and up)\n"
    "  fog     a fog volume: the unit ball of density 1 - (r/R)^2 (dense: half the grid)\n"
    "  noise   a fog volume: clouds of multi-octave noise over the whole grid (a fifth of it)\n"
    "The first three are the unit sphere, 15/16 of the grid across, centred on index 0 (world\n"
    "about [-1,1]^3); all have voxel size 32/(15 N); occupied voxels are those whose centre's signed distance\n"
    "d (voxels) has -W < d <= 0, with normals; the fields' are those whose density is above 0,\n"
    "with their density. Progress: the percentage of the grid done and the time left.\n"
    "Interrupted (SIGINT, SIGTERM, SIGHUP), it writes no store and leaves what was at store/\n"
    "as it was, and says so. Exit codes: 0 done, 1 the generation failed or was interrupted,\n"
    "2 bad command line.\n"};

struct GenCommand {
  vox::gen::GenerateOptions options;
  bool quiet = false, have_size = false;
};

// Applies one option of kOptions.
vox::Status ApplyGenFlag(GenCommand* c, const std::string& a, const std::string& v) {
  vox::gen::GenerateOptions& o = c->options;
  int64_t n = 0;
  if (a == "--force") {
    o.force = true;
  } else if (a == "--quiet") {
    c->quiet = true;
  } else if (a == "--no-lod") {
    o.lod = false;
  } else if (a == "--levels") {
    o.levels = v;
  } else if (a == "--band") {
    if (!vox::ParseDouble(v, &o.band))
      return vox::InvalidArgumentError("--band " + v + ": not a finite number");
  } else if (!vox::ParseInt(v, int64_t{-1000000000000}, int64_t{1000000000000}, &n)) {
    return vox::InvalidArgumentError(a + " " + v + ": not a whole number");
  } else if (a == "--size") {
    if (n < 0)
      return vox::InvalidArgumentError("--size " + v + ": must be a power of two from 2 to 2^20");
    o.size = uint64_t(n);
    c->have_size = true;
  } else if (n < -1000000 || n > 1000000) {
    return vox::InvalidArgumentError(a + " " + v + ": out of range");
  } else if (a == "--threads") {
    if (n < 0 || n > vox::kMaxThreads)
      return vox::InvalidArgumentError("--threads " + v + ": must be in 1.." +
                                       std::to_string(vox::kMaxThreads) + " (or 0 for all cores)");
    o.threads = int(n);
  } else if (a == "--zstd-level") {
    o.zstd_level = int(n);
  } else {
    o.normal_bits = int(n);
  }
  return vox::OkStatus();
}

int UsageError(const std::string& message) {
  return vox::UsageError(kCommandLine.program, message);
}

std::atomic<bool> g_cancel{false};
extern "C" void OnSignal(int) { g_cancel.store(true); }

}  // namespace

static int RunTool(int argc, char** argv) {
  GenCommand command;
  vox::gen::GenerateOptions& o = command.options;
  const bool& quiet = command.quiet;
  std::vector<std::string> positional;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return ApplyGenFlag(&command, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &positional))
    return *exit_code;
  if (positional.size() != 2)
    return UsageError("expected a shape and an output store directory, got " +
                      std::to_string(positional.size()) + " arguments");
  o.shape = positional[0];
  o.output = positional[1];
  if (!command.have_size) return UsageError("--size is required");
  if (vox::Status s = vox::gen::ValidateOptions(o); !s.ok()) return UsageError(s.message());

  struct sigaction sa = {};
  sa.sa_handler = OnSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGHUP, &sa, nullptr);
  o.cancel = &g_cancel;

  // A bar on a terminal, a line per 10% otherwise: the grid's volume
  // decided so far, and the time left at the rate so far.
  vox::Progress display(vox::ChooseProgressMode(stderr, quiet), stderr);
  vox::gen::GenerateProgressReport last;
  const auto text = [&last](double elapsed) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "vox-gen: %3d%% of the grid, %s bricks, %s voxels",
                  int(last.done * 100 / last.total),
                  vox::Progress::Count(double(last.bricks)).c_str(),
                  vox::Progress::Count(double(last.voxels)).c_str());
    std::string t = buf;
    if (last.done > 0 && last.done < last.total && elapsed >= 1.0)
      t += ", " +
           vox::Progress::Duration(elapsed * double(last.total - last.done) / double(last.done)) +
           " left";
    return t;
  };
  auto progress = [&](const vox::gen::GenerateProgressReport& r) {
    last = r;
    if (r.done < r.total) return display.Update(r.done, r.total, text);
    display.Finish(r.done, r.total, text);
    display.Message(o.lod ? "vox-gen: writing the index and the level-of-detail pyramid"
                          : "vox-gen: writing the index");
  };
  auto stats = quiet ? vox::gen::Generate(o) : vox::gen::Generate(o, progress);
  if (!stats.ok()) {
    // An interrupted run's message says what was kept, as it is.
    const vox::Status& status = stats.status();
    std::fprintf(stderr, "vox-gen: %s\n",
                 g_cancel.load() ? status.message().c_str() : status.ToString().c_str());
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

// vox-ingest: reads an OpenVDB grid and writes a vox store.
//   vox-ingest data.vdb store/ [options]
//   vox-ingest --add-lod store/ [--zstd-level L] [--force] [--quiet]
//   vox-ingest data.npy store/ [--voxel-size S] [--origin X,Y,Z] [--threshold T] [options]
//   vox-ingest data.raw store/ --shape X,Y,Z --dtype float32 [...]   (array_input.h)
// An array is written into the store brick by brick (ingest/array_ingest.h,
// IngestArray), streamed from its mapped file.
// The options are tools/common/options.h's ingest table (vox-ingest --help).
// Exit codes: 0 done, 1 the ingest failed (or its child process crashed),
// 2 bad command line, 128+N killed by signal N (SIGINT, SIGTERM, SIGKILL: the
// temporary store directory is removed).
//
// The ingest runs in a child process (vox-ingest re-executed) under tools/common/supervisor.h, which
// reports a crash of the child (a signal, a sanitizer's exit) as a crash,
// naming the file and the signal, and removes the child's temporary store.
#include <unistd.h>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "ingest/ingest.h"
#include "ingest/limits.h"
#include "storage/lod.h"
#include "core/util/memory_budget.h"
#include "tools/common/cli.h"
#include "tools/common/options.h"
#include "tools/common/signals.h"
#include "tools/common/supervisor.h"
#include "tools/common/tool_main.h"
#include "tools/ingest/array_input.h"

namespace {

const vox::CommandLineSpec kCommandLine{
    "vox-ingest",
    "vox-ingest data.vdb store/ [options]\n"
    "vox-ingest --add-lod store/ [--zstd-level L] [--force] [--quiet]\n"
    "vox-ingest data.npy|data.raw store/ [--shape X,Y,Z --dtype D] [--voxel-size S] "
    "[--origin X,Y,Z] [--threshold T] [options]",
    "Reads a grid of the OpenVDB file data.vdb and writes the vox store store/ (with its "
    "level-of-detail pyramid), or adds the pyramid to an existing store.",
    vox::IngestOptionTable(),
    "Exit codes: 0 done, 1 the ingest failed (or its child process crashed), 2 bad command\n"
    "line, 128+N killed by signal N (the temporary store directory is removed; with --resume\n"
    "the bricks written so far are kept for the next run).\n"};

// The array input (null: a .vdb) and the command line as given, which the
// ingest child is re-executed with.
vox::ArrayInput* g_array = nullptr;
char** g_argv = nullptr;
int g_argc = 0;

int UsageError(const std::string& message) {
  return vox::UsageError(kCommandLine.program, message);
}

}  // namespace

static int IngestAndReport(const vox::IngestOptions& o, const vox::IngestLimits& limits,
                           bool quiet);

static int RunTool(int argc, char** argv) {
  vox::IngestCommand command;
  vox::IngestOptions& o = command.options;
  std::vector<std::string> positional;
  // The command line as given (an array's flags included).
  o.command_line = g_array ? vox::CommandLineText("vox-ingest", g_argc, g_argv)
                           : vox::CommandLineText("vox-ingest", argc, argv);
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return vox::ApplyIngestFlag(&command, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &positional))
    return *exit_code;
  const bool quiet = command.quiet;
  const std::string& add_lod = command.add_lod;
  if (!add_lod.empty()) {
    if (!positional.empty())
      return UsageError("--add-lod takes one store and no other input or output");
    if (!o.lod) return UsageError("--add-lod and --no-lod exclude each other");
    if (o.zstd_level < 1 || o.zstd_level > 22) return UsageError("--zstd-level must be in 1..22");
    vox::LodBuildOptions lo;
    lo.zstd_level = o.zstd_level;
    lo.normal_bits = o.normal_bits;
    lo.threads = o.threads;
    lo.force = o.force;
    // Interrupted: the pyramid's temporary (STORE/.lod.tmp-PID-*) goes.
    vox::StartOutputSignalThread("vox-ingest", {add_lod + "/lod"});
    auto st = vox::BuildLod(add_lod, lo);
    if (!st.ok()) {
      const int code = vox::ToolExitCode(1);  // an interrupt exits with 128 + N instead
      std::fprintf(stderr, "vox-ingest: --add-lod: %s\n", st.status().ToString().c_str());
      return code;
    }
    if (!quiet) {
      uint64_t bricks = 0;
      for (uint64_t b : st->bricks) bricks += b;
      std::fprintf(stderr,
                   "added %s/lod: %d levels, %llu bricks, from %llu base bricks in %.2f s\n",
                   add_lod.c_str(), st->levels, (unsigned long long)bricks,
                   (unsigned long long)st->base_bricks_read, st->seconds);
    }
    return 0;
  }
  if (positional.size() != 2)
    return UsageError("expected an input .vdb file and an output store directory, got " +
                      std::to_string(positional.size()) + " arguments");
  o.input = positional[0];
  o.output = positional[1];
  if (vox::Status s = vox::CheckIngestCommand(command); !s.ok()) return UsageError(s.message());

  return vox::RunSupervised(g_array ? g_argv : argv, o.input, o.output,
                            [&] { return IngestAndReport(o, command.limits, quiet); },
                            o.resume);
}

static int IngestAndReport(const vox::IngestOptions& o, const vox::IngestLimits& limits,
                           bool quiet) {
  vox::StartSignalThread(o.output, o.resume);
  std::unique_ptr<vox::ProgressSink> progress;
  if (!quiet) progress = vox::MakeStderrProgress(isatty(STDERR_FILENO) != 0);
  const std::unique_ptr<vox::ProgressSink> test_hook = vox::MakeTestHookProgress(progress.get());
  vox::ProgressSink* sink = test_hook ? test_hook.get() : progress.get();
  vox::StatusOr<vox::IngestStats> stats = vox::InvalidArgumentError("no ingest");
  if (g_array != nullptr) {
    vox::ArrayPlacement place = g_array->placement;
    place.threshold = o.threshold.value_or(0.0);
    stats = vox::IngestArray(g_array->array->view(), place, o, sink);
  } else {
    stats = vox::Ingest(o, limits, sink);
  }
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
                 "%.2f s, bricks %.2f s, finish %.2f s; level of detail: %d levels, %.2f s)\n",
                 o.output.c_str(), (unsigned long long)s.occupied_voxels,
                 (unsigned long long)s.bricks, s.meta.brick_level,
                 s.meta.levels - s.meta.brick_level, (unsigned long long)s.active_voxels,
                 s.seconds_total, rate / 1e6, s.threads, s.seconds_open, s.seconds_bbox,
                 s.seconds_bricks, s.seconds_finish, s.lod_levels, s.seconds_lod);
  }
  return 0;
}

int main(int argc, char** argv) {
  // A .npy or raw input: mapped here, ingested brick by brick (array_input.h).
  vox::ArrayInput array = vox::PrepareArrayInput(argc, argv);
  if (!array.error.empty()) {
    std::fprintf(stderr, "vox-ingest: %s\n", array.error.c_str());
    return array.exit_code;
  }
  if (!array.wanted) return vox::ToolMain("vox-ingest", argc, argv, RunTool);
  g_array = &array;
  g_argv = argv;
  g_argc = argc;
  std::vector<char*> args;
  for (std::string& a : array.args) args.push_back(a.data());
  args.push_back(nullptr);
  return vox::ToolMain("vox-ingest", int(array.args.size()), args.data(), RunTool);
}

// vox-render: renders a vox store to a tiled OpenEXR by discrete ray tracing.
// Parses its command line (tools/common/cli.h) into RenderJobOptions with
// the option table of tools/common/options.h and calls vox::RunRenderJob.
#include <cstdio>
#include <string>
#include <vector>

#include "render/job.h"
#include "tools/common/cli.h"
#include "tools/common/options.h"
#include "tools/common/signals.h"
#include "tools/common/tool_main.h"

namespace {

const vox::CommandLineSpec kCommandLine{
    "vox-render",
    "vox-render STORE_DIR [options]",
    "Renders the vox store STORE_DIR to a tiled OpenEXR by discrete ray tracing: one frame, or a "
    "sequence of frames (--cam with an array of cameras, --turntable).",
    vox::RenderOptionTable(),
    "Outputs never replace inputs (store files, camera, scene) or each other; -o must end in\n"
    ".exr, --preview in .png; every frame's are checked before any work. A frame's outputs are\n"
    "published together when it is done; SIGINT, SIGTERM and SIGHUP remove the unfinished ones\n"
    "(earlier frames stay) and exit 128 + the signal. Exit codes: 0 done, 1 failed, 2 bad\n"
    "command line.\n"};

}  // namespace

static int RunTool(int argc, char** argv) {
  vox::RenderJobOptions o;
  bool io_threads_given = false;
  std::vector<std::string> stores;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    io_threads_given |= flag == "--io-threads";
    return vox::ApplyRenderFlag(&o, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &stores))
    return *exit_code;
  const auto usage_error = [](const std::string& message) {
    return vox::UsageError(kCommandLine.program, message);
  };
  if (stores.empty()) return usage_error("no store given");
  if (stores.size() > 1)
    return usage_error("more than one store given: " + stores[0] + " and " + stores[1]);
  o.store_dir = stores[0];
  if (io_threads_given && !o.prefetch)
    return usage_error("--io-threads sets the background readers of --prefetch; without "
                       "--prefetch the render threads read bricks themselves");
  // SIGINT, SIGTERM, SIGHUP (Slurm's time limit): stop, remove the
  // temporaries, keep earlier outputs, exit 128 + the signal.
  vox::StartOutputSignalThread("vox-render", {o.exr_path, o.preview_path, o.stats_path});
  o.on_outputs = vox::AddSignalOutputs;  // every frame's, once the sequence is known
  vox::Status s = vox::RunRenderJob(o);
  if (!s.ok()) {
    const int code = vox::ToolExitCode(1);  // an interrupt exits with 128 + N instead
    fprintf(stderr, "vox-render: %s\n", s.ToString().c_str());
    return code;
  }
  return 0;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-render", argc, argv, RunTool); }

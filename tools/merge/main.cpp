// vox-merge: assembles the partial EXRs of `vox-render --tiles I/N` into one
// image. Parses its command line (tools/common/cli.h; kOptions below) and
// calls vox::MergeParts.
#include <cstdio>
#include <string>
#include <vector>

#include "render/exr.h"
#include "render/merge.h"
#include "core/util/atomic_file.h"
#include "tools/common/cli.h"
#include "tools/common/signals.h"
#include "tools/common/tool_main.h"

namespace {

struct MergeCommand {
  std::string out, preview;
  bool quiet = false;
};

constexpr vox::OptionSpec kOptions[] = {
    {"-o", vox::FlagArity::kValue, "out.exr", "Output", "the merged image (required; ends in .exr)"},
    {"--preview", vox::FlagArity::kValue, "out.png", "Output",
     "also write an 8-bit sRGB PNG (ends in .png)"},
    {"--quiet", vox::FlagArity::kSwitch, "", "Output", "no summary on stderr"},
};

const vox::CommandLineSpec kCommandLine{
    "vox-merge", "vox-merge PART.exr... -o out.exr [--preview out.png] [--quiet]",
    "Assembles the partial EXRs of `vox-render --tiles I/N` into one image. Checks that the "
    "parts belong together (same image, tiles, camera, scene, split, store), that every part "
    "1..N is present once and complete, and writes the image.",
    kOptions,
    "The outputs must not be parts or each other. SIGINT, SIGTERM and SIGHUP remove the\n"
    "unfinished outputs and exit 128 + the signal.\n"};

// Applies one option of kOptions.
vox::Status ApplyMergeFlag(MergeCommand* c, const std::string& a, const std::string& v) {
  if (a == "-o") {
    c->out = v;
  } else if (a == "--preview") {
    c->preview = v;
  } else if (a == "--quiet") {
    c->quiet = true;
  } else {
    return vox::InvalidArgumentError("unknown option " + a);
  }
  return vox::OkStatus();
}

int UsageError(const std::string& message) {
  return vox::UsageError(kCommandLine.program, message);
}

}  // namespace

static int RunTool(int argc, char** argv) {
  MergeCommand command;
  std::vector<std::string> parts;
  const auto apply = [&](const std::string& flag, const std::string& value) {
    return ApplyMergeFlag(&command, flag, value);
  };
  if (auto exit_code = vox::ParseCommandLine(kCommandLine, argc, argv, apply, &parts))
    return *exit_code;
  const std::string &out = command.out, &preview = command.preview;
  if (out.empty()) return UsageError("no output given (-o out.exr)");
  if (parts.empty()) return UsageError("no part files given");
  vox::MergeResult result;
  vox::StartOutputSignalThread("vox-merge", {out, preview});
  vox::Status s = vox::MergeParts(parts, out, &result, preview);
  if (!s.ok()) {
    const int code = vox::ToolExitCode(1);  // an interrupt exits with 128 + N instead
    fprintf(stderr, "vox-merge: %s\n", s.ToString().c_str());
    return code;
  }
  if (!command.quiet)
    fprintf(stderr,
            "vox-merge: %s from %d parts (%lld tiles); render time %.3f s max, %.3f s total\n",
            out.c_str(), result.parts, (long long)result.tiles, result.max_render_seconds,
            result.sum_render_seconds);
  return 0;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-merge", argc, argv, RunTool); }

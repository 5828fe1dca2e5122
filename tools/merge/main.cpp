// vox-merge: assembles the partial EXRs of `vox-render --tiles I/N` into one
// image. Parses flags and calls vox::MergeParts.
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "render/exr.h"
#include "render/merge.h"
#include "storage/atomic_file.h"
#include "tools/common/flags.h"
#include "tools/common/signals.h"
#include "tools/common/tool_main.h"

namespace {

const char kUsage[] =
    "usage: vox-merge PART.exr... -o out.exr [--preview out.png] [--quiet]\n"
    "  Checks that the parts belong together (same image, tiles, camera, scene, split,\n"
    "  store), that every part 1..N is present once and complete, and writes the image.\n"
    "  The outputs must not be parts or each other; -o ends in .exr, --preview in .png.\n"
    "  SIGINT, SIGTERM and SIGHUP remove the unfinished outputs and exit 128 + the signal.\n";

int Usage(const std::string& error) {
  if (!error.empty()) fprintf(stderr, "vox-merge: %s\n", error.c_str());
  fprintf(stderr, "%s", kUsage);
  return 2;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  std::vector<std::string> parts;
  std::string out, preview;
  bool quiet = false;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      fprintf(stdout, "%s", kUsage);
      return 0;
    } else if (a == "-o" || a == "--preview") {
      const std::optional<std::string> v = flags.Value();
      if (!v) return Usage(a + " needs a value");
      (a == "-o" ? out : preview) = *v;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (flags.IsFlag()) {
      return Usage("unknown flag " + a);
    } else {
      parts.push_back(a);
    }
  }
  if (out.empty()) return Usage("no output given (-o out.exr)");
  if (parts.empty()) return Usage("no part files given");
  vox::MergeResult result;
  vox::StartOutputSignalThread("vox-merge", {out, preview});
  vox::Status s = vox::MergeParts(parts, out, &result, preview);
  if (!s.ok()) {
    const int code = vox::ToolExitCode(1);  // an interrupt exits with 128 + N instead
    fprintf(stderr, "vox-merge: %s\n", s.ToString().c_str());
    return code;
  }
  if (!quiet)
    fprintf(stderr,
            "vox-merge: %s from %d parts (%lld tiles); render time %.3f s max, %.3f s total\n",
            out.c_str(), result.parts, (long long)result.tiles, result.max_render_seconds,
            result.sum_render_seconds);
  return 0;
}

int main(int argc, char** argv) { return vox::ToolMain("vox-merge", argc, argv, RunTool); }

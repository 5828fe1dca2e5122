// vox-render: renders a vox store to a tiled OpenEXR by discrete ray tracing.
// Parses flags into RenderJobOptions (tools/common/options.h) and calls
// vox::RunRenderJob.
#include <cstdio>
#include <optional>
#include <string>

#include "render/job.h"
#include "tools/common/flags.h"
#include "tools/common/options.h"
#include "tools/common/signals.h"
#include "tools/common/tool_main.h"

namespace {

const char kUsage[] =
    "usage: vox-render STORE_DIR [--cam cam.json] [--scene scene.json] [-o out.exr]\n"
    "                  [--turntable N] [--frames A-B]\n"
    "                  [--preview out.png] [--split N1+N2|N1] [--single-step] [--memory-mb M]\n"
    "                  [--cache-mb M] [--threads N] [--tile-size T] [--tiles I/N] [--stats stats.json] [--quiet]\n"
    "                  [--layers normal,voxel,position,distance] [--size WxH] [--view AZ,EL]\n"
    "                  [--save-cam cam.json] [--lod F] [--silhouette-aa G] [--float]\n"
    "                  [--compression C] [--prefetch [--io-threads N]] [--no-read-windows] [--no-beam]\n"
    "                  [--allow-huge]\n"
    "  --cam        camera JSON (world space of the source VDB; docs/usage.md); without it a\n"
    "               default camera frames the whole volume. An array of cameras is a frame\n"
    "               sequence: one frame per camera\n"
    "  --turntable N  a sequence of N frames around the camera's look-at point (--cam's, --view's\n"
    "               or the default camera's): the same distance and elevation, azimuth steps\n"
    "               of 360/N degrees about its up axis; frame 1 is the camera itself\n"
    "  --frames A-B render frames A to B of the sequence (1-based, inclusive; or N: frame N\n"
    "               alone), e.g. one chunk per Slurm array task\n"
    "  --size WxH   image size, overriding the camera JSON's (default 1024x1024 without --cam)\n"
    "  --view AZ,EL look at the volume's centre from azimuth AZ and elevation EL (degrees),\n"
    "               framing its world box (--cam's lens, size and up, or the default camera's)\n"
    "  --save-cam F write the camera used as camera JSON (reusable with --cam); in a sequence,\n"
    "               a pattern writes each frame's camera, a plain name the array of the\n"
    "               rendered frames' cameras (with the last frame)\n"
    "  --scene      lights, materials, background, volume, max_depth, samples_per_pixel\n"
    "  -o           output EXR (default render.exr); R G B A (half float, premultiplied) and\n"
    "               Z (float, planar camera depth); docs/usage.md has the layout. A printf\n"
    "               frame pattern (out.%04d.exr; also for --preview and --stats) numbers\n"
    "               the frames from 1; a sequence of several frames requires one\n"
    "  --float      write R G B A as 32-bit float\n"
    "  --compression  EXR tile compression: rle (default), zip (smaller, slower), zips, piz\n"
    "               or none (default for --tiles parts, which vox-merge recompresses)\n"
    "  --layers     extra EXR layers: normal (N.X N.Y N.Z), voxel (voxel.i voxel.j voxel.k),\n"
    "               position (P.X P.Y P.Z), distance (along the ray)\n"
    "  --preview    also write an 8-bit sRGB PNG\n"
    "  --split      first-step levels of the two-step traversal (N1, or N1+N2 = levels)\n"
    "  --single-step  one DDA step over the whole grid (grids of at most 2^20)\n"
    "  --memory-mb  memory the whole process may use, in MiB (or with a unit: 2G);\n"
    "               default: the memory cgroup's limit (Slurm --mem, a container), or 3/4 of\n"
    "               MemAvailable if smaller; the brick cache, pinned bricks and buffers are\n"
    "               sized within it (1/8 kept as headroom)\n"
    "  --cache-mb   decompressed brick cache, inside the memory budget (default: what the\n"
    "               budget leaves)\n"
    "  --prefetch   read bricks in the background: the next tiles' first bricks, and a\n"
    "               pixel's missing brick while other pixels are shaded (same image; helps\n"
    "               on busy machines, reads more bytes under tight memory limits)\n"
    "  --io-threads background reader threads of --prefetch (default 8; refused without\n"
    "               --prefetch, where the render threads read)\n"
    "  --no-read-windows  read each brick record alone, not with its file neighbours\n"
    "               (by default a miss reads the window of records around it, up to 1 MiB,\n"
    "               kept compressed in 1/8 of the brick cache, at most 64 MiB)\n"
    "  --no-beam    trace every primary ray from its start (no beam start distances;\n"
    "               the same image, slower)\n"
    "  --threads    render threads (default: all cores)\n"
    "  --tile-size  tile side in pixels (default 64)\n"
    "  --tiles I/N  render only part I (1-based) of N; assemble the parts with vox-merge\n"
    "               (a part holds only its tiles: it is for vox-merge, not other EXR tools)\n"
    "  --lod F      level of detail: a ray stops at the first occupied cell of the store's\n"
    "               pyramid (store/lod/) whose size is at most F times the pixel's cone\n"
    "               width there. Default: 1 when the store has a pyramid (a huge volume\n"
    "               seen whole costs what its image costs; wherever a voxel covers a pixel\n"
    "               the frame is the exact one, bit for bit), else 0. --lod 0: the paper's\n"
    "               exact frame everywhere. See docs/lod.md\n"
    "  --silhouette-aa G  with level of detail, a coarse stop next to a miss is shaded again\n"
    "               from GxG sub-pixel rays with cones G times narrower, so its alpha is the\n"
    "               covered fraction (default 4; 0: coarse silhouettes stay whole cells)\n"
    "  --stats      write counters and timings as JSON (per frame: its number and camera)\n"
    "  --quiet      no progress output\n"
    "  --allow-huge render a frame of more than 2^28 pixels (16384x16384); the estimated\n"
    "               EXR size must still fit the output's disk\n"
    "  Outputs never replace inputs (store files, camera, scene) or each other; -o must\n"
    "  end in .exr, --preview in .png; every frame's are checked before any work. A frame's\n"
    "  outputs are published together when it is done; SIGINT, SIGTERM and SIGHUP remove\n"
    "  the unfinished ones (earlier frames stay) and exit 128 + the signal.\n";

int Usage(const std::string& error) {
  if (!error.empty()) fprintf(stderr, "vox-render: %s\n", error.c_str());
  fprintf(stderr, "%s", kUsage);
  return 2;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  vox::RenderJobOptions o;
  vox::FlagReader flags(argc, argv);
  bool io_threads_given = false;
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      fprintf(stdout, "%s", kUsage);
      return 0;
    } else if (flags.IsFlag()) {
      const vox::FlagArity arity = vox::RenderFlagArity(a);
      if (arity == vox::FlagArity::kUnknown) return Usage("unknown flag " + a);
      std::optional<std::string> value;
      if (arity == vox::FlagArity::kValue && !(value = flags.Value()))
        return Usage(a + " needs a value");
      vox::Status s = vox::ApplyRenderFlag(&o, a, value.value_or(""));
      if (!s.ok()) return Usage(s.message());
      io_threads_given |= a == "--io-threads";
    } else if (o.store_dir.empty()) {
      o.store_dir = a;
    } else {
      return Usage("more than one store given: " + o.store_dir + " and " + a);
    }
  }
  if (o.store_dir.empty()) return Usage("no store given");
  if (io_threads_given && !o.prefetch)
    return Usage("--io-threads sets the background readers of --prefetch; without --prefetch "
                 "the render threads read bricks themselves");
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

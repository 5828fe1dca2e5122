// vox-render: renders a vox store to a tiled OpenEXR by discrete ray tracing.
// Parses flags into RenderJobOptions and calls vox::RunRenderJob.
#include <climits>
#include <cstdio>
#include <new>
#include <optional>
#include <string>

#include "render/camera.h"
#include "render/job.h"
#include "storage/memory_budget.h"
#include "tools/common/flags.h"

namespace {

const char kUsage[] =
    "usage: vox-render STORE_DIR [--cam cam.json] [--scene scene.json] [-o out.exr]\n"
    "                  [--preview out.png] [--split N1+N2|N1] [--single-step] [--memory-mb M]\n"
    "                  [--cache-mb M] [--threads N] [--tile-size T] [--tiles I/N] [--stats stats.json] [--quiet]\n"
    "                  [--layers normal,voxel] [--size WxH]\n"
    "  --cam        camera JSON (world space of the source VDB); without it a default\n"
    "               camera frames the whole volume (--size sets its image size, default "
    "1024x1024)\n"
    "  --scene      lights, materials, background, volume, max_depth, samples_per_pixel\n"
    "  -o           output EXR (default render.exr); channels R G B A Z\n"
    "  --layers     extra EXR layers: normal (N.x N.y N.z), voxel (voxel.i voxel.j voxel.k)\n"
    "  --preview    also write an 8-bit sRGB PNG\n"
    "  --split      first-step levels of the two-step traversal (N1, or N1+N2 = levels)\n"
    "  --single-step  one DDA step over the whole grid (grids of at most 2^20)\n"
    "  --memory-mb  memory the whole process may use, in MiB (or with a unit: 2G);\n"
    "               default: the memory cgroup's limit (Slurm --mem, a container), or 3/4 of\n"
    "               MemAvailable if smaller; the brick cache, pinned bricks and buffers are\n"
    "               sized within it (1/16 kept as headroom)\n"
    "  --cache-mb   decompressed brick cache, inside the memory budget (default: what the\n"
    "               budget leaves)\n"
    "  --prefetch   read the next tiles' bricks ahead while tracing (experimental)\n"
    "  --threads    render threads (default: all cores)\n"
    "  --tile-size  tile side in pixels (default 64)\n"
    "  --tiles I/N  render only part I (1-based) of N; assemble the parts with vox-merge\n"
    "  --stats      write counters and timings as JSON\n"
    "  --quiet      no progress output\n";

int Usage(const std::string& error) {
  if (!error.empty()) fprintf(stderr, "vox-render: %s\n", error.c_str());
  fprintf(stderr, "%s", kUsage);
  return 2;
}

}  // namespace

static int RunTool(int argc, char** argv) {
  vox::RenderJobOptions o;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      fprintf(stdout, "%s", kUsage);
      return 0;
    } else if (a == "--single-step") {
      o.single_step = true;
    } else if (a == "--quiet") {
      o.quiet = true;
    } else if (a == "--prefetch") {
      o.prefetch = true;
    } else if (a == "--cam" || a == "--scene" || a == "-o" || a == "--preview" || a == "--split" ||
               a == "--cache-mb" || a == "--memory-mb" || a == "--threads" || a == "--tile-size" || a == "--tiles" ||
               a == "--stats" || a == "--layers" || a == "--size") {
      const std::optional<std::string> value = flags.Value();
      if (!value) return Usage(a + " needs a value");
      const std::string& v = *value;
      if (a == "--cam")
        o.camera_path = v;
      else if (a == "--scene")
        o.scene_path = v;
      else if (a == "-o")
        o.exr_path = v;
      else if (a == "--preview")
        o.preview_path = v;
      else if (a == "--split")
        o.split = v;
      else if (a == "--stats")
        o.stats_path = v;
      else if (a == "--cache-mb") {
        int mb = 0;
        if (!vox::ParseInt(v, 1, 1 << 22, &mb))
          return Usage("--cache-mb '" + v + "': expected a positive integer");
        o.cache_mb = size_t(mb);
      } else if (a == "--memory-mb") {
        auto bytes = vox::ParseMemorySize("--memory-mb", v);
        if (!bytes.ok()) return Usage(bytes.status().message());
        o.memory_bytes = *bytes;
      } else if (a == "--threads") {
        if (!vox::ParseInt(v, 0, vox::kMaxThreads, &o.threads))
          return Usage("--threads '" + v + "': expected 0.." + std::to_string(vox::kMaxThreads));
      } else if (a == "--tile-size") {
        if (!vox::ParseInt(v, INT_MIN, INT_MAX, &o.tile_size))
          return Usage("--tile-size '" + v + "': expected an integer");
      } else if (a == "--tiles") {
        auto part = vox::ParsePartSpec(v);
        if (!part.ok()) return Usage(part.status().message());
        o.part = *part;
      } else if (a == "--layers") {
        for (const std::string& item : vox::SplitList(v)) {
          if (item == "normal")
            o.layers.normal = true;
          else if (item == "voxel")
            o.layers.voxel = true;
          else
            return Usage("--layers: unknown layer '" + item + "' (normal, voxel)");
        }
      } else if (a == "--size") {
        size_t x = v.find('x');
        if (x == std::string::npos ||
            !vox::ParseInt(v.substr(0, x), 1, vox::kMaxImageSide, &o.default_width) ||
            !vox::ParseInt(v.substr(x + 1), 1, vox::kMaxImageSide, &o.default_height))
          return Usage("--size '" + v + "': expected WxH");
      }
    } else if (flags.IsFlag()) {
      return Usage("unknown flag " + a);
    } else if (o.store_dir.empty()) {
      o.store_dir = a;
    } else {
      return Usage("more than one store given: " + o.store_dir + " and " + a);
    }
  }
  if (o.store_dir.empty()) return Usage("no store given");
  vox::Status s = vox::RunRenderJob(o);
  if (!s.ok()) {
    fprintf(stderr, "vox-render: %s\n", s.ToString().c_str());
    return 1;
  }
  return 0;
}

// Allocation failures anywhere (an image, a brick, a table sized from input)
// end with a clear message and exit 1, never an abort.
int main(int argc, char** argv) {
  try {
    return RunTool(argc, argv);
  } catch (const std::bad_alloc&) {
    fprintf(stderr, "vox-render: out of memory (std::bad_alloc); try smaller sizes or budgets\n");
    return 1;
  }
}

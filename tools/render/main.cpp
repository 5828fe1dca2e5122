// vox-render: renders a vox store to a tiled OpenEXR by discrete ray tracing.
// Parses flags into RenderJobOptions and calls vox::RunRenderJob.
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "render/camera.h"
#include "render/job.h"

namespace {

const char kUsage[] =
    "usage: vox-render STORE_DIR [--cam cam.json] [--scene scene.json] [-o out.exr]\n"
    "                  [--preview out.png] [--split N1+N2|N1] [--single-step] [--cache-mb M]\n"
    "                  [--threads N] [--tile-size T] [--tiles I/N] [--stats stats.json] [--quiet]\n"
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
    "  --cache-mb   decompressed brick cache budget (default 1024)\n"
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

bool ParseInt(const char* s, long lo, long hi, int* out) {
  char* end = nullptr;
  errno = 0;
  long v = std::strtol(s, &end, 10);
  if (errno != 0 || end == s || *end != '\0' || v < lo || v > hi) return false;
  *out = int(v);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  vox::RenderJobOptions o;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&](const char* flag) -> const char* {
      if (i + 1 >= argc) return nullptr;
      (void)flag;
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      fprintf(stdout, "%s", kUsage);
      return 0;
    } else if (a == "--single-step") {
      o.single_step = true;
    } else if (a == "--quiet") {
      o.quiet = true;
    } else if (a == "--cam" || a == "--scene" || a == "-o" || a == "--preview" || a == "--split" ||
               a == "--cache-mb" || a == "--threads" || a == "--tile-size" || a == "--tiles" ||
               a == "--stats" || a == "--layers" || a == "--size") {
      const char* v = value(a.c_str());
      if (!v) return Usage(a + " needs a value");
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
        if (!ParseInt(v, 1, 1 << 22, &mb))
          return Usage(std::string("--cache-mb '") + v + "': expected a positive integer");
        o.cache_mb = size_t(mb);
      } else if (a == "--threads") {
        if (!ParseInt(v, 0, 4096, &o.threads))
          return Usage(std::string("--threads '") + v + "': expected 0..4096");
      } else if (a == "--tile-size") {
        if (!ParseInt(v, INT_MIN, INT_MAX, &o.tile_size))
          return Usage(std::string("--tile-size '") + v + "': expected an integer");
      } else if (a == "--tiles") {
        auto part = vox::ParsePartSpec(v);
        if (!part.ok()) return Usage(part.status().message());
        o.part = *part;
      } else if (a == "--layers") {
        std::string list = v;
        size_t start = 0;
        while (start <= list.size()) {
          size_t comma = list.find(',', start);
          std::string item =
              list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
          if (item == "normal")
            o.layers.normal = true;
          else if (item == "voxel")
            o.layers.voxel = true;
          else
            return Usage("--layers: unknown layer '" + item + "' (normal, voxel)");
          if (comma == std::string::npos) break;
          start = comma + 1;
        }
      } else if (a == "--size") {
        std::string s = v;
        size_t x = s.find('x');
        if (x == std::string::npos ||
            !ParseInt(s.substr(0, x).c_str(), 1, vox::kMaxImageSide, &o.default_width) ||
            !ParseInt(s.substr(x + 1).c_str(), 1, vox::kMaxImageSide, &o.default_height))
          return Usage("--size '" + s + "': expected WxH");
      }
    } else if (!a.empty() && a[0] == '-') {
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

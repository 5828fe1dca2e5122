#include "tools/common/options.h"

#include <climits>
#include <cmath>
#include <variant>

#include "core/shapes.h"
#include "render/camera.h"
#include "render/frame_sequence.h"
#include "render/lod.h"
#include "storage/lod.h"
#include "storage/memory_budget.h"
#include "storage/store.h"
#include "storage/store_budget.h"
#include "tools/common/flags.h"

namespace vox {
namespace {

bool OneOf(std::string_view flag, std::initializer_list<std::string_view> names) {
  for (std::string_view n : names)
    if (flag == n) return true;
  return false;
}

}  // namespace

FlagArity IngestFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--force", "--quiet", "--no-lod"})) return FlagArity::kSwitch;
  if (OneOf(flag, {"--grid", "--levels", "--isovalue", "--threshold", "--color", "--zstd-level",
                   "--normal-bits", "--threads", "--memory-mb", "--add-lod", "--max-voxels"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyIngestFlag(IngestCommand* c, const std::string& flag, const std::string& v) {
  IngestOptions& o = c->options;
  if (flag == "--force") {
    o.force = true;
  } else if (flag == "--quiet") {
    c->quiet = true;
  } else if (flag == "--no-lod") {
    o.lod = false;
  } else if (flag == "--add-lod") {
    c->add_lod = v;
  } else if (flag == "--max-voxels") {
    double d = 0;
    if (!ParseDouble(v, &d) || !(d >= 1) || d > 1e18 || d != std::floor(d))
      return InvalidArgumentError("--max-voxels " + v + ": must be a whole number of voxels (1e10 is fine)");
    c->limits.max_tile_voxels = uint64_t(d);
  } else if (flag == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o.memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (flag == "--grid") {
    o.grid_name = v;
  } else if (flag == "--levels") {
    o.levels = v;
  } else if (flag == "--color") {
    o.color_grid = v;
  } else if (flag == "--normal-bits") {
    if (!ParseInt(v, 8, 16, &o.normal_bits))
      return InvalidArgumentError("--normal-bits " + v +
                                  ": must be a whole number of bits in 8..16");
  } else if (flag == "--isovalue" || flag == "--threshold") {
    double d;
    if (!ParseDouble(v, &d)) return InvalidArgumentError(flag + " " + v + ": not a finite number");
    (flag == "--isovalue" ? o.isovalue : o.threshold) = d;
  } else if (flag == "--threads" || flag == "--zstd-level") {
    if (!ParseInt(v, -1000000, 1000000, flag == "--threads" ? &o.threads : &o.zstd_level))
      return InvalidArgumentError(flag + " " + v + ": not a whole number");
  } else {
    return InvalidArgumentError("unknown option " + flag);
  }
  return OkStatus();
}

Status CheckIngestCommand(const IngestCommand& c) {
  const IngestOptions& o = c.options;
  if (o.threads < 0 || o.threads > kMaxThreads)
    return InvalidArgumentError("--threads " + std::to_string(o.threads) + ": must be in 1.." +
                                std::to_string(kMaxThreads) + " (or 0 for all cores)");
  if (o.zstd_level < 1 || o.zstd_level > 22)
    return InvalidArgumentError("--zstd-level must be in 1..22");
  if (auto lv = ParseLevels(o.levels); !lv.ok()) return InvalidArgumentError(lv.status().message());
  return OkStatus();
}

FlagArity RenderFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--single-step", "--quiet", "--prefetch", "--no-prefetch", "--float",
                   "--allow-huge", "--read-windows", "--no-read-windows", "--beam", "--no-beam"}))
    return FlagArity::kSwitch;
  if (OneOf(flag, {"--cam", "--scene", "-o", "--preview", "--split", "--cache-mb", "--memory-mb",
                   "--threads", "--tile-size", "--tiles", "--stats", "--layers", "--size",
                   "--io-threads", "--lod", "--silhouette-aa", "--compression", "--view",
                   "--save-cam", "--turntable", "--frames"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyRenderFlag(RenderJobOptions* o, const std::string& a, const std::string& v) {
  if (v.empty() && OneOf(a, {"--cam", "--scene", "-o", "--preview", "--stats"}))
    return InvalidArgumentError(a + " '': an empty path names no file");
  if (a == "--single-step") {
    o->single_step = true;
  } else if (a == "--quiet") {
    o->quiet = true;
  } else if (a == "--prefetch") {
    o->prefetch = true;
  } else if (a == "--no-prefetch") {  // once accepted and silently the default: refused, saying so
    return InvalidArgumentError("--no-prefetch was removed: bricks are read without prefetching "
                                "unless --prefetch is given");
  } else if (a == "--read-windows" || a == "--no-read-windows") {
    o->read_windows = a == "--read-windows";
  } else if (a == "--beam" || a == "--no-beam") {
    o->beam = a == "--beam";
  } else if (a == "--lod") {
    VOX_ASSIGN_OR_RETURN(o->lod, ParseLodFactor("--lod", v));
  } else if (a == "--silhouette-aa") {
    if (!ParseInt(v, 0, kMaxSilhouetteGrid, &o->silhouette_grid))
      return InvalidArgumentError("--silhouette-aa '" + v + "': expected 0 (off) or 1.." +
                                  std::to_string(kMaxSilhouetteGrid));
  } else if (a == "--float") {
    o->layers.float_color = true;
  } else if (a == "--allow-huge") {
    o->allow_huge = true;
  } else if (a == "--compression") {
    VOX_ASSIGN_OR_RETURN(o->compression, ParseExrCompression(v));
  } else if (a == "--io-threads") {
    if (!ParseInt(v, 1, kMaxIoThreads, &o->io_threads))
      return InvalidArgumentError("--io-threads '" + v + "': expected 1.." + std::to_string(kMaxIoThreads));
  } else if (a == "--cam") {
    o->camera_path = v;
  } else if (a == "--scene") {
    o->scene_path = v;
  } else if (a == "-o") {
    o->exr_path = v;
  } else if (a == "--preview") {
    o->preview_path = v;
  } else if (a == "--split") {
    o->split = v;
  } else if (a == "--stats") {
    o->stats_path = v;
  } else if (a == "--cache-mb") {
    int mb = 0;
    if (!ParseInt(v, 1, 1 << 22, &mb))
      return InvalidArgumentError("--cache-mb '" + v + "': expected a positive integer");
    o->cache_mb = size_t(mb);
  } else if (a == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o->memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (a == "--threads") {
    if (!ParseInt(v, 0, kMaxThreads, &o->threads))
      return InvalidArgumentError("--threads '" + v + "': expected 0.." + std::to_string(kMaxThreads));
  } else if (a == "--tile-size") {
    if (!ParseInt(v, INT_MIN, INT_MAX, &o->tile_size))
      return InvalidArgumentError("--tile-size '" + v + "': expected an integer");
  } else if (a == "--tiles") {
    VOX_ASSIGN_OR_RETURN(o->part, ParsePartSpec(v));
  } else if (a == "--layers") {
    for (const std::string& item : SplitList(v)) {
      if (item == "normal")
        o->layers.normal = true;
      else if (item == "voxel")
        o->layers.voxel = true;
      else if (item == "position")
        o->layers.position = true;
      else if (item == "distance")
        o->layers.distance = true;
      else
        return InvalidArgumentError("--layers: unknown layer '" + item +
                                    "' (normal, voxel, position, distance)");
    }
  } else if (a == "--size") {
    const size_t x = v.find('x');
    if (x == std::string::npos || !ParseInt(v.substr(0, x), 1, kMaxImageSide, &o->default_width) ||
        !ParseInt(v.substr(x + 1), 1, kMaxImageSide, &o->default_height))
      return InvalidArgumentError("--size '" + v + "': expected WxH");
    o->size_given = true;
  } else if (a == "--view") {
    const size_t comma = v.find(',');
    double az = 0, el = 0;
    if (comma == std::string::npos || !ParseDouble(v.substr(0, comma), &az) ||
        !ParseDouble(v.substr(comma + 1), &el) || !(std::abs(el) < 90))
      return InvalidArgumentError("--view '" + v +
                                  "': expected AZIMUTH,ELEVATION in degrees, elevation in (-90, 90)");
    o->view = std::make_pair(az, el);
  } else if (a == "--save-cam") {
    o->save_camera_path = v;
  } else if (a == "--turntable") {
    if (!ParseInt(v, 1, kMaxFrames, &o->turntable))
      return InvalidArgumentError("--turntable '" + v + "': expected a number of frames, 1.." +
                                  std::to_string(kMaxFrames));
  } else if (a == "--frames") {
    VOX_ASSIGN_OR_RETURN(o->frames, ParseFrameRange(v));
  } else {
    return InvalidArgumentError("unknown flag " + a);
  }
  return OkStatus();
}

FlagArity ProbeFlagArity(std::string_view flag) {
  if (OneOf(flag, {"--single-step", "--stats"})) return FlagArity::kSwitch;
  if (OneOf(flag, {"--generate", "--split", "--memory-mb", "--brick-level", "--cache-mb",
                   "--fixed", "--tracer", "--lod", "--cone-rad", "--cone-width"}))
    return FlagArity::kValue;
  return FlagArity::kUnknown;
}

Status ApplyProbeFlag(ProbeOptions* o, const std::string& a, const std::string& v) {
  if (a == "--single-step") {
    o->single_step = true;
  } else if (a == "--stats") {
    o->stats = true;
  } else if (a == "--generate") {
    o->generate = v;
  } else if (a == "--tracer") {
    if (v != "render" && v != "long-double")
      return InvalidArgumentError("--tracer '" + v + "': expected render or long-double");
    o->tracer = v;
  } else if (a == "--split") {
    o->split = v;
  } else if (a == "--memory-mb") {
    VOX_ASSIGN_OR_RETURN(o->memory_bytes, ParseMemorySize("--memory-mb", v));
  } else if (a == "--lod") {
    VOX_ASSIGN_OR_RETURN(o->lod, ParseLodFactor(a, v));
  } else if (a == "--cone-rad" || a == "--cone-width") {
    double d = 0;
    if (!ParseDouble(v, &d) || d < 0)
      return InvalidArgumentError(a + " '" + v + "': expected a finite number >= 0");
    (a == "--cone-rad" ? o->cone_rad : o->cone_width) = d;
  } else if (a == "--brick-level" || a == "--cache-mb" || a == "--fixed") {
    int64_t n = 0;
    if (a == "--fixed" && v == "auto") {
      o->fixed = 0;
    } else if (!ParseInt(v, 0, a == "--cache-mb" ? INT64_MAX >> 20 : INT32_MAX, &n)) {
      return InvalidArgumentError(a + ": '" + v + "' is not a non-negative integer");
    } else if (a == "--brick-level") {
      o->brick_level = int(n);
    } else if (a == "--cache-mb") {
      o->cache_mb = size_t(n);
    } else {
      o->fixed = int(n);
    }
  } else {
    return InvalidArgumentError("unknown option " + a);
  }
  return OkStatus();
}

}  // namespace vox

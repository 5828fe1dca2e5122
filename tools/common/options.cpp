#include "tools/common/options.h"

#include <sys/sysinfo.h>

#include <cfloat>
#include <climits>
#include <cmath>
#include <variant>

#include "core/shapes.h"
#include "render/camera.h"
#include "render/frame_sequence.h"
#include "render/limits.h"
#include "render/lod.h"
#include "render/tiles.h"
#include "storage/lod.h"
#include "core/util/memory_budget.h"
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

constexpr FlagArity kSwitch = FlagArity::kSwitch, kValue = FlagArity::kValue;

// The headings of the tools' help; each tool lists its groups in the order
// of its table. "" hides an option (accepted, not shown).
constexpr const char* kLodGroup = "Level of detail";
constexpr const char* kOutputGroup = "Output";
constexpr const char* kHidden = "";

// The flags vox-render and vox-probe share: one entry each, in both tables,
// applied by ApplySharedFlag.
constexpr const char* kTracingGroup = "Tracing";
constexpr const char* kMemoryGroup = "Memory and I/O";
constexpr OptionSpec kSplitOption{"--split", FlagArity::kValue, "N1+N2|N1", kTracingGroup,
                                  "first-step levels of the two-step traversal (N1, or N1+N2 = "
                                  "levels)"};
constexpr OptionSpec kSingleStepOption{"--single-step", FlagArity::kSwitch, "", kTracingGroup,
                                       "one DDA step over the whole grid (grids of at most 2^20)"};
constexpr OptionSpec kMemoryOption{
    "--memory-mb", FlagArity::kValue, "M", kMemoryGroup,
    "memory the whole process may use, in MiB (or with a unit: 2G); default: the memory "
    "cgroup's limit (Slurm --mem, a container), or 3/4 of MemAvailable if smaller; the brick "
    "cache, pinned bricks and buffers are sized within it (1/8 kept as headroom)"};
constexpr OptionSpec kCacheOption{
    "--cache-mb", FlagArity::kValue, "M", kMemoryGroup,
    "decompressed brick cache, inside the memory budget (default: what the budget leaves)"};

// A --memory-mb value (ParseMemorySize) that the machine can hold: at most
// its RAM and swap together, the most any budget could use.
StatusOr<uint64_t> ParseMemoryFlag(const std::string& flag, const std::string& v) {
  VOX_ASSIGN_OR_RETURN(const uint64_t bytes, ParseMemorySize(flag, v));
  struct sysinfo si;
  if (sysinfo(&si) != 0) return bytes;
  const uint64_t machine = (uint64_t(si.totalram) + uint64_t(si.totalswap)) * si.mem_unit;
  if (machine == 0 || bytes <= machine) return bytes;
  return InvalidArgumentError(flag + " '" + v + "': " + std::to_string(bytes >> 20) +
                              " MiB is more memory than this machine has (" +
                              std::to_string(machine >> 20) +
                              " MiB of RAM and swap); expected 1.." +
                              std::to_string(machine >> 20) + " MiB");
}

// The largest brick cache --cache-mb takes, in MiB (4 TiB).
constexpr int64_t kMaxCacheMb = int64_t(1) << 22;

// The fields of vox-render's and vox-probe's options the shared flags set.
struct SharedFields {
  std::string* split;
  bool* single_step;
  uint64_t* memory_bytes;
  size_t* cache_mb;
};

// "N1" or "N1+N2", whole numbers: the form ParseSplit (core/tracer.h) reads
// once the store's levels are known.
bool SplitSyntaxOk(const std::string& v) {
  const size_t plus = v.find('+');
  auto number = [](const std::string& s) {
    return !s.empty() && s.size() <= 3 && s.find_first_not_of("0123456789") == std::string::npos;
  };
  return number(v.substr(0, plus)) && (plus == std::string::npos || number(v.substr(plus + 1)));
}

// Applies a flag of both tools; nullopt for any other flag.
std::optional<Status> ApplySharedFlag(const SharedFields& f, const std::string& a,
                                      const std::string& v) {
  if (a == "--single-step") {
    *f.single_step = true;
  } else if (a == "--split") {
    if (!SplitSyntaxOk(v))
      return InvalidArgumentError("--split '" + v + "': expected N1+N2 or N1, whole numbers of "
                                  "levels (e.g. 6+5)");
    *f.split = v;
  } else if (a == "--memory-mb") {
    StatusOr<uint64_t> bytes = ParseMemoryFlag(a, v);
    if (!bytes.ok()) return bytes.status();
    *f.memory_bytes = *bytes;
  } else if (a == "--cache-mb") {
    int64_t mb = 0;
    if (!ParseInt(v, 1, kMaxCacheMb, &mb))
      return InvalidArgumentError("--cache-mb '" + v + "': expected a whole number of MiB in 1.." +
                                  std::to_string(kMaxCacheMb) + " (4 TiB)");
    *f.cache_mb = size_t(mb);
  } else {
    return std::nullopt;
  }
  return OkStatus();
}

constexpr const char* kInputGroup = "Input grid";
constexpr const char* kStoreGroup = "Store";
constexpr const char* kIngestMemoryGroup = "Memory and threads";

constexpr OptionSpec kIngestOptions[] = {
    {"--grid", kValue, "NAME", kInputGroup, "the grid to ingest (default: the first float or double grid)"},
    {"--isovalue", kValue, "F", kInputGroup,
     "level sets: a voxel is occupied when active and value <= F (default 0)"},
    {"--threshold", kValue, "F", kInputGroup,
     "fog volumes: occupied when active and density > F (default 0)"},
    {"--color", kValue, "GRID", kInputGroup, "a vec3s/vec3d grid sampled as each voxel's RGB colour"},
    {"--source", kValue, "TEXT", kInputGroup,
     "what the store records as its source (vox-info's source; default: the input file)"},
    {"--temperature", kValue, "GRID", kInputGroup,
     "a second float/double grid of the file (a fire's temperature, in Kelvin) sampled at each "
     "voxel, for blackbody fog (scene.json volume.blackbody)"},
    {"--max-voxels", kValue, "N", kInputGroup,
     "the most voxels active tiles may expand to (default 1e10); a grid whose occupied tiles "
     "cover more is refused"},
    {"--levels", kValue, "N1+N2|auto", kStoreGroup,
     "auto (32^3 bricks) or N1+N2: N1 resident levels above bricks of N2 levels (2^N2 voxels "
     "per axis); each at most 20, N1+N2 at most 40"},
    {"--zstd-level", kValue, "L", kStoreGroup, "brick compression level, 1..22 (default 3)"},
    {"--normal-bits", kValue, "B", kStoreGroup,
     "level sets: bits per octahedral normal component, 8..16 (default 16, max error 0.004 "
     "degrees; 12: 0.06 degrees and a smaller store)"},
    {"--no-lod", kSwitch, "", kLodGroup,
     "skip the level-of-detail pyramid (store/lod/, for vox-render --lod; written by default)"},
    {"--add-lod", kValue, "STORE", kLodGroup,
     "add the level-of-detail pyramid to an existing store (--force replaces one it has)"},
    {"--threads", kValue, "N", kIngestMemoryGroup, "worker threads (default: all cores)"},
    {"--memory-mb", kValue, "N", kIngestMemoryGroup,
     "memory the ingest may hold, MiB or with a unit (512, 2G; default: the process's memory "
     "cgroup limit or available memory)"},
    {"--force", kSwitch, "", kOutputGroup, "replace an existing store"},
    {"--resume", kSwitch, "", kOutputGroup,
     "resumable: build the store in .STORE.resume beside it with a journal of its bricks, kept "
     "when the run is interrupted or killed; run again with --resume to keep the verified bricks "
     "and write the rest"},
    {"--quiet", kSwitch, "", kOutputGroup, "no progress output"},
};

}  // namespace

OptionTable IngestOptionTable() { return kIngestOptions; }

Status ApplyIngestFlag(IngestCommand* c, const std::string& flag, const std::string& v) {
  IngestOptions& o = c->options;
  if (flag == "--resume") {
    o.resume = true;
  } else if (flag == "--force") {
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
    VOX_ASSIGN_OR_RETURN(o.memory_bytes, ParseMemoryFlag(flag, v));
  } else if (flag == "--grid") {
    o.grid_name = v;
  } else if (flag == "--levels") {
    o.levels = v;
  } else if (flag == "--color") {
    o.color_grid = v;
  } else if (flag == "--source") {
    o.source = v;
  } else if (flag == "--temperature") {
    o.temperature_grid = v;
  } else if (flag == "--normal-bits") {
    if (!ParseInt(v, 8, 16, &o.normal_bits))
      return InvalidArgumentError("--normal-bits " + v +
                                  ": must be a whole number of bits in 8..16");
  } else if (flag == "--isovalue" || flag == "--threshold") {
    double d;
    if (!ParseDouble(v, &d)) return InvalidArgumentError(flag + " " + v + ": not a finite number");
    // Grid values are floats (or doubles read as such): beyond a float's
    // range every active voxel, or none, would be occupied.
    if (std::fabs(d) > FLT_MAX)
      return InvalidArgumentError(flag + " " + v + ": outside a grid value's range, -3.4e38.." +
                                  "3.4e38 (a float's)");
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

namespace {

constexpr const char* kCameraGroup = "Camera and scene";
constexpr const char* kFramesGroup = "Frame sequences";
constexpr const char* kPartsGroup = "Parallel runs";

constexpr OptionSpec kRenderOptions[] = {
    {"--cam", kValue, "cam.json", kCameraGroup,
     "camera JSON (world space of the source VDB; docs/usage.md); without it a default camera "
     "frames the whole volume. An array of cameras is a frame sequence: one frame per camera"},
    {"--scene", kValue, "scene.json", kCameraGroup,
     "lights, materials, background, volume, max_depth, samples_per_pixel"},
    {"--size", kValue, "WxH", kCameraGroup,
     "image size, overriding the camera JSON's (default 1024x1024 without --cam)"},
    {"--view", kValue, "AZ,EL", kCameraGroup,
     "look at the volume's centre from azimuth AZ and elevation EL (degrees), framing its world "
     "box (--cam's lens, size and up, or the default camera's)"},
    {"--save-cam", kValue, "cam.json", kCameraGroup,
     "write the camera used as camera JSON (reusable with --cam); in a sequence, a pattern "
     "writes each frame's camera, a plain name the array of the rendered frames' cameras (with "
     "the last frame)"},
    {"--turntable", kValue, "N", kFramesGroup,
     "a sequence of N frames around the camera's look-at point (--cam's, --view's or the "
     "default camera's): the same distance and elevation, azimuth steps of 360/N degrees about "
     "its up axis; frame 1 is the camera itself"},
    {"--frames", kValue, "A-B", kFramesGroup,
     "render frames A to B of the sequence (1-based, inclusive; or N: frame N alone), e.g. one "
     "chunk per Slurm array task"},
    {"--skip-done", kSwitch, "", kFramesGroup,
     "skip a frame whose outputs exist and are verified as this frame of this job (the EXR's "
     "vox: header and every tile readable; the other outputs no older): a requeued task "
     "renders only what is missing or partial"},
    {"-o", kValue, "out.exr", kOutputGroup,
     "output EXR (default render.exr); R G B A (half float, premultiplied) and Z (float, planar "
     "camera depth); docs/usage.md has the layout. A printf frame pattern (out.%04d.exr; also "
     "for --preview and --stats) numbers the frames from 1; a sequence of several frames "
     "requires one"},
    {"--float", kSwitch, "", kOutputGroup, "write R G B A as 32-bit float"},
    {"--compression", kValue, "C", kOutputGroup,
     "EXR tile compression: rle (default), zip (smaller, slower), zips, piz or none (default for "
     "--tiles parts, which vox-merge recompresses)"},
    {"--layers", kValue, "LIST", kOutputGroup,
     "extra EXR layers, comma-separated: normal (N.X N.Y N.Z), voxel (voxel.i voxel.j voxel.k), "
     "position (P.X P.Y P.Z), distance (along the ray)"},
    {"--preview", kValue, "out.png", kOutputGroup, "also write an 8-bit sRGB PNG"},
    {"--stats", kValue, "stats.json", kOutputGroup,
     "write counters and timings as JSON (per frame: its number and camera)"},
    {"--allow-huge", kSwitch, "", kOutputGroup,
     "render a frame of more than 2^28 pixels (16384x16384); the estimated EXR size must still "
     "fit the output's disk"},
    {"--quiet", kSwitch, "", kOutputGroup, "no progress output"},
    {"--lod", kValue, "F", kLodGroup,
     "level of detail: a ray stops at the first occupied cell of the store's pyramid "
     "(store/lod/) whose size is at most F times the pixel's cone width there. Default: 1 when "
     "the store has a pyramid (a huge volume seen whole costs what its image costs; wherever a "
     "voxel covers a pixel the frame is the exact one, bit for bit), else 0. --lod 0: the "
     "paper's exact frame everywhere. See docs/lod.md"},
    {"--silhouette-aa", kValue, "G", kLodGroup,
     "with level of detail, a coarse stop next to a miss is shaded again from GxG sub-pixel rays "
     "with cones G times narrower, so its alpha is the covered fraction (default 4; 0: coarse "
     "silhouettes stay whole cells)"},
    kMemoryOption,
    kCacheOption,
    {"--prefetch", kSwitch, "", kMemoryGroup,
     "read bricks in the background: the next tiles' first bricks (exact frames only), and a "
     "pixel's missing brick while other pixels are shaded (same image; off by default: cold frames "
     "wait only for the disk without it, and its threads cost CPU)"},
    {"--io-threads", kValue, "N", kMemoryGroup,
     "background reader threads of --prefetch (default 8; refused without --prefetch, where the "
     "render threads read)"},
    {"--no-read-windows", kSwitch, "", kMemoryGroup,
     "read each brick record alone, not with its file neighbours (by default a miss reads the "
     "window of records around it, up to 1 MiB, kept compressed in 1/8 of the brick cache, at "
     "most 64 MiB)"},
    {"--read-windows", kSwitch, "", kHidden, "the default: read windows of records"},
    {"--no-prefetch", kSwitch, "", kHidden, "removed: refused with a message"},
    kSplitOption,
    kSingleStepOption,
    {"--no-beam", kSwitch, "", kTracingGroup,
     "trace every primary ray from its start (no beam start distances; the same image, slower)"},
    {"--beam", kSwitch, "", kHidden, "the default: beam start distances"},
    {"--threads", kValue, "N", kPartsGroup, "render threads (default: all cores)"},
    {"--tile-size", kValue, "T", kPartsGroup, "tile side in pixels, 8..4096 (default 64)"},
    {"--tiles", kValue, "I/N", kPartsGroup,
     "render only part I (1-based) of N; assemble the parts with vox-merge (a part holds only "
     "its tiles: it is for vox-merge, not other EXR tools)"},
};

}  // namespace

OptionTable RenderOptionTable() { return kRenderOptions; }

Status ApplyRenderFlag(RenderJobOptions* o, const std::string& a, const std::string& v) {
  if (v.empty() && OneOf(a, {"--cam", "--scene", "-o", "--preview", "--stats", "--save-cam"}))
    return InvalidArgumentError(a + " '': an empty path names no file");
  if (auto shared = ApplySharedFlag({&o->split, &o->single_step, &o->memory_bytes, &o->cache_mb},
                                    a, v))
    return *shared;
  if (a == "--quiet") {
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
  } else if (a == "--skip-done") {
    o->skip_done = true;
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
  } else if (a == "--stats") {
    o->stats_path = v;
  } else if (a == "--threads") {
    if (!ParseInt(v, 0, kMaxThreads, &o->threads))
      return InvalidArgumentError("--threads '" + v + "': expected 0.." + std::to_string(kMaxThreads));
  } else if (a == "--tile-size") {
    if (!ParseInt(v, kMinTileSize, kMaxTileSize, &o->tile_size))
      return InvalidArgumentError("--tile-size '" + v + "': expected a tile side in pixels, " +
                                  std::to_string(kMinTileSize) + ".." +
                                  std::to_string(kMaxTileSize));
  } else if (a == "--tiles") {
    VOX_ASSIGN_OR_RETURN(o->part, ParsePartSpec(v));
    if (o->part.count > kMaxTiles)  // more parts than any image has tiles
      return InvalidArgumentError("--tiles '" + v + "': N must be in 1.." +
                                  std::to_string(kMaxTiles) + ", the most tiles an image has");
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
    return InvalidArgumentError("unknown option " + a);
  }
  return OkStatus();
}

namespace {

constexpr const char* kSourceGroup = "Source";

constexpr OptionSpec kProbeOptions[] = {
    {"--generate", kValue, "SHAPE", kSourceGroup,
     "trace a generated shape instead of a store: sphere:N, torus:N, cubes:N, noise:N (N voxels "
     "per axis), corner:L (2^L grid)"},
    {"--brick-level", kValue, "L", kSourceGroup,
     "the generated shape's brick level (levels per brick; default: its levels - 5, at least 1)"},
    {"--tracer", kValue, "render|long-double", kTracingGroup,
     "render (default) answers as vox-render traces (double set-up, the store's occupied box); "
     "long-double with a long-double set-up (docs/accuracy.md)"},
    kSplitOption,
    kSingleStepOption,
    {"--fixed", kValue, "auto|64|128", kTracingGroup,
     "fixed-point word (auto: 64 up to 2^26 grids, else 128)"},
    {"--stats", kSwitch, "", kTracingGroup, "print the traversal counters on stderr"},
    {"--lod", kValue, "F", kLodGroup,
     "stop at the first occupied cell of the store's level-of-detail pyramid whose size is at "
     "most F times the ray's cone width (W + R t |dir| voxels at t); prints 'lod L i j k t' for "
     "a cell of level L > 0"},
    {"--cone-rad", kValue, "R", kLodGroup,
     "the cone's spread in radians: its width grows by R t |dir| voxels (required by --lod)"},
    {"--cone-width", kValue, "W", kLodGroup,
     "the cone's width at the ray's origin, in voxels (default 0; with --lod)"},
    kMemoryOption,
    kCacheOption,
};

}  // namespace

OptionTable ProbeOptionTable() { return kProbeOptions; }

Status ApplyProbeFlag(ProbeOptions* o, const std::string& a, const std::string& v) {
  if (auto shared = ApplySharedFlag({&o->split, &o->single_step, &o->memory_bytes, &o->cache_mb},
                                    a, v))
    return *shared;
  if (a == "--stats") {
    o->stats = true;
  } else if (a == "--generate") {
    o->generate = v;
  } else if (a == "--tracer") {
    if (v != "render" && v != "long-double")
      return InvalidArgumentError("--tracer '" + v + "': expected render or long-double");
    o->tracer = v;
  } else if (a == "--lod") {
    VOX_ASSIGN_OR_RETURN(o->lod, ParseLodFactor(a, v));
  } else if (a == "--cone-rad" || a == "--cone-width") {
    double d = 0;
    if (!ParseDouble(v, &d) || d < 0)
      return InvalidArgumentError(a + " '" + v + "': expected a finite number >= 0");
    (a == "--cone-rad" ? o->cone_rad : o->cone_width) = d;
  } else if (a == "--brick-level" || a == "--fixed") {
    int64_t n = 0;
    if (a == "--fixed" && v == "auto") {
      o->fixed = 0;
    } else if (!ParseInt(v, 0, INT32_MAX, &n)) {
      return InvalidArgumentError(a + ": '" + v + "' is not a non-negative integer");
    } else if (a == "--brick-level") {
      o->brick_level = int(n);
    } else {
      o->fixed = int(n);
    }
  } else {
    return InvalidArgumentError("unknown option " + a);
  }
  return OkStatus();
}

}  // namespace vox

#include "render/internal/job_plan.h"

#include <sys/statvfs.h>

#include <algorithm>
#include <utility>

#include "core/util/atomic_file.h"
#include "core/util/file.h"
#include "core/util/memory_budget.h"
#include "core/util/path_identity.h"
#include "render/grid_transform.h"
#include "render/limits.h"
#include "render/lod.h"
#include "render/tiles.h"
#include "storage/store_budget.h"

namespace vox::job_internal {
namespace {

// "out.exr" -> "out.%04d.exr", for the message asking for a pattern.
std::string SuggestPattern(const std::string& path) {
  std::string escaped;  // a '%' of the name is written %% in a pattern
  for (const char c : path) escaped += c == '%' ? std::string("%%") : std::string(1, c);
  const size_t slash = escaped.find_last_of('/');
  const size_t dot = escaped.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash))
    return escaped + ".%04d";
  return escaped.substr(0, dot) + ".%04d" + escaped.substr(dot);
}

// The output flags of a frame and their paths (patterns or plain names).
std::vector<std::pair<std::string, std::string>> OutputRoles(const RenderJobOptions& options) {
  return {{"-o", options.exr_path},
          {"--preview", options.preview_path},
          {"--stats", options.stats_path},
          {"--save-cam", options.save_camera_path}};
}

// The inputs no output may be: the store's files, the camera, the scene.
std::vector<NamedPath> JobInputs(const RenderJobOptions& options) {
  std::vector<NamedPath> inputs = StoreInputs(options.store_dir);
  inputs.push_back({"camera", options.camera_path});
  inputs.push_back({"scene", options.scene_path});
  return inputs;
}

bool SaveCameraPattern(const RenderJobOptions& options) {
  const StatusOr<bool> pattern = IsFramePattern("--save-cam", options.save_camera_path);
  return pattern.ok() && *pattern;
}

// The one camera of a run or the base of its turntable: `given` (or the
// default framing of the volume's world box), then --size and --view, which
// override it.
StatusOr<Camera> JobCamera(const RenderJobOptions& options, const Camera* given,
                           const std::string& source, const StoreMeta& meta) {
  glm::dvec3 lo, hi;
  WorldBounds(meta, &lo, &hi);
  Camera camera = given != nullptr
                      ? *given
                      : DefaultCamera(lo, hi, options.default_width, options.default_height);
  if (options.size_given) {
    camera.width = options.default_width;
    camera.height = options.default_height;
    VOX_RETURN_IF_ERROR(camera.Finalize("--size"));
  }
  if (options.view) {
    VOX_ASSIGN_OR_RETURN(camera,
                         OrbitCamera(camera, lo, hi, options.view->first, options.view->second));
  }
  // A given camera may be anywhere; the default one and --view's are near.
  if (given != nullptr && !options.view)
    VOX_RETURN_IF_ERROR(CheckCameraDistance(camera, lo, hi).WithContext(source));
  return camera;
}

}  // namespace

Status CheckJobOptions(const RenderJobOptions& options) {
  if (!options.preview_path.empty() && options.exr_path.empty())
    return InvalidArgumentError("--preview needs an EXR output (-o)");
  if (!options.preview_path.empty() && !options.part.whole())
    return InvalidArgumentError(
        "--preview needs the whole image; with --tiles, preview the vox-merge output");
  if (options.threads < 0)
    return InvalidArgumentError("threads " + std::to_string(options.threads) +
                                ": must not be negative (0: all cores)");
  if (options.io_threads < 1 || options.io_threads > kMaxIoThreads)
    return InvalidArgumentError("--io-threads " + std::to_string(options.io_threads) +
                                ": must be 1.." + std::to_string(kMaxIoThreads));
  if (options.lod && !(*options.lod >= 0 && std::isfinite(*options.lod)))
    return InvalidArgumentError("--lod " + std::to_string(*options.lod) +
                                ": must be finite and >= 0 (0: exact)");
  if (options.silhouette_grid < 0 || options.silhouette_grid > kMaxSilhouetteGrid)
    return InvalidArgumentError("--silhouette-aa " + std::to_string(options.silhouette_grid) +
                                ": must be 0 (off) or 1.." + std::to_string(kMaxSilhouetteGrid));
  if (options.single_step && !options.split.empty())
    return InvalidArgumentError("--split and --single-step both choose the split; give one");
  return OkStatus();
}

// A frame over kMaxPixelsUnlessAllowed is refused without --allow-huge;
// the EXR's uncompressed size (an upper bound) is printed and must fit the
// free space of its directory.
Status CheckFrameSize(const RenderJobOptions& options, const std::string& exr_path,
                      const Camera& camera, bool say) {
  // The layout's own limit first (the most tiles an image may have).
  VOX_RETURN_IF_ERROR(CheckTileCount(camera.width, camera.height,
                                     std::clamp(options.tile_size, kMinTileSize, kMaxTileSize)));
  if (const std::string w = PartCountWarning(camera.width, camera.height, options.tile_size,
                                              options.part);
      say && !w.empty())
    fprintf(options.log, "vox-render: warning: %s\n", w.c_str());
  const int64_t pixels = int64_t(camera.width) * int64_t(camera.height);
  const std::string size = std::to_string(camera.width) + "x" + std::to_string(camera.height);
  if (pixels > kMaxPixelsUnlessAllowed && !options.allow_huge)
    return InvalidArgumentError("a " + size + " frame has " + std::to_string(pixels) +
                                " pixels, more than " + std::to_string(kMaxPixelsUnlessAllowed) +
                                "; pass --allow-huge to render it");
  if (exr_path.empty()) return OkStatus();
  const int bytes_per_pixel = (options.layers.float_color ? 16 : 8) + 4 +
                              (options.layers.normal ? 12 : 0) + (options.layers.voxel ? 12 : 0);
  const double fraction = options.part.whole() ? 1.0 : 1.0 / options.part.count;
  const uint64_t estimate = uint64_t(double(pixels) * bytes_per_pixel * fraction);
  if (say)
    fprintf(options.log, "vox-render: %s: %s, at most %.1f MiB\n", exr_path.c_str(),
            size.c_str(), double(estimate) / double(kMiB));
  std::string dir, name;
  SplitPath(exr_path, &dir, &name);
  struct statvfs vfs;
  if (statvfs(dir.c_str(), &vfs) != 0) return OkStatus();
  const uint64_t free_bytes = uint64_t(vfs.f_bavail) * uint64_t(vfs.f_frsize);
  if (estimate > free_bytes)
    return ResourceExhaustedError("-o " + exr_path + ": the " + size + " image may take " +
                                  std::to_string(estimate >> 20) + " MiB and " + dir + " has " +
                                  std::to_string(free_bytes >> 20) + " MiB free");
  return OkStatus();
}


// Reads the cameras (before the store is opened: their number decides the
// outputs) and the frames to render. `keep`: the image is kept in memory,
// which holds one frame.
StatusOr<JobSequence> PlanSequence(const RenderJobOptions& options, bool keep) {
  JobSequence seq;
  // --size: the size of cameras that give none (and, in JobCamera, of all).
  const ImageSize size{options.default_width, options.default_height};
  const ImageSize* fill = options.size_given ? &size : nullptr;
  if (!options.camera_path.empty()) {
    VOX_ASSIGN_OR_RETURN(seq.given, LoadCameras(options.camera_path, fill));
    seq.source = options.camera_path;
  } else if (!options.camera_json.empty()) {
    VOX_ASSIGN_OR_RETURN(seq.given, ParseCameras(options.camera_json, "camera", fill));
    seq.source = "camera";
  }
  const std::string cameras = std::to_string(seq.given.size()) + " cameras";
  if (seq.given.size() > 1 && options.turntable > 0)
    return InvalidArgumentError("--turntable turns one camera; " + seq.source + " holds " + cameras);
  if (seq.given.size() > 1 && options.view)
    return InvalidArgumentError("--view places one camera; with the " + cameras + " of " +
                                seq.source + " every frame would show the same view");
  if (options.turntable < 0 || options.turntable > kMaxFrames)
    return InvalidArgumentError("--turntable " + std::to_string(options.turntable) +
                                ": must be 1.." + std::to_string(kMaxFrames));
  seq.count = options.turntable > 0 ? options.turntable : std::max<int>(1, int(seq.given.size()));
  VOX_ASSIGN_OR_RETURN(seq.range,
                       FramesToRender(seq.count, options.frames ? &*options.frames : nullptr));
  if (keep && seq.frames() > 1)
    return InvalidArgumentError("an image kept in memory is one frame; the sequence has " +
                                std::to_string(seq.count) +
                                " frames: choose one with frames=N (or render them with vox-render)");
  return seq;
}

Status CheckJobOutputs(const RenderJobOptions& options, const JobSequence& seq) {
  std::vector<NamedPath> patterns;
  for (const auto& [role, path] : OutputRoles(options)) {
    if (path.empty()) continue;
    VOX_ASSIGN_OR_RETURN(const bool pattern, IsFramePattern(role, path));
    if (!pattern && seq.count > 1 && role != "--save-cam")
      return InvalidArgumentError(role + " " + path + ": the sequence has " +
                                  std::to_string(seq.count) +
                                  " frames; give a frame pattern such as " + SuggestPattern(path) +
                                  " (frames are numbered from 1)");
    patterns.push_back({role, path});
  }
  // The run's first and last frames' paths (a pattern's directory and
  // extension are every frame's unless its number is in them: then each
  // frame's are checked when it comes).
  for (const int n : {seq.range.first, seq.range.last}) {
    const FrameOutputs f = FrameFiles(options, seq, n);
    const std::string frame = seq.count > 1 ? "frame " + std::to_string(n) + "'s " : "";
    for (const std::string* path : {&f.exr, &f.preview, &f.stats, &f.save_camera})
      if (!path->empty()) VOX_RETURN_IF_ERROR(CheckOutputPath(*path));
    if (!f.exr.empty()) VOX_RETURN_IF_ERROR(CheckExtension(frame + "-o", f.exr, ".exr"));
    if (!f.preview.empty())
      VOX_RETURN_IF_ERROR(CheckExtension(frame + "--preview", f.preview, ".png"));
  }
  return CheckFrameOutputs(JobInputs(options), patterns, seq.range);
}

FrameOutputs FrameFiles(const RenderJobOptions& options, const JobSequence& seq, int number) {
  FrameOutputs f;
  f.number = number;
  f.exr = ExpandFramePattern(options.exr_path, number);
  f.preview = ExpandFramePattern(options.preview_path, number);
  f.stats = ExpandFramePattern(options.stats_path, number);
  if (SaveCameraPattern(options) || number == seq.range.last)
    f.save_camera = ExpandFramePattern(options.save_camera_path, number);
  return f;
}

Status CheckFrameFiles(const RenderJobOptions& options, const JobSequence& seq,
                       const FrameOutputs& f) {
  const std::string frame = seq.count > 1 ? "frame " + std::to_string(f.number) + "'s " : "";
  std::vector<NamedPath> named;
  for (const auto& [role, path] : {std::pair<std::string, const std::string*>{"-o", &f.exr},
                                   {"--preview", &f.preview},
                                   {"--stats", &f.stats},
                                   {"--save-cam", &f.save_camera}}) {
    if (path->empty()) continue;
    VOX_RETURN_IF_ERROR(CheckOutputPath(*path));
    named.push_back({frame + role, *path});
  }
  return CheckDistinctPaths(JobInputs(options), named);
}

Status PrepareCameras(const RenderJobOptions& options, const StoreMeta& meta, JobSequence* seq) {
  glm::dvec3 lo, hi;
  WorldBounds(meta, &lo, &hi);
  seq->centre = 0.5 * (lo + hi);
  const bool say = !options.quiet;
  if (seq->given.size() > 1) {
    seq->cameras.clear();
    for (size_t i = 0; i < seq->given.size(); ++i) {
      VOX_ASSIGN_OR_RETURN(
          Camera camera,
          JobCamera(options, &seq->given[i], seq->source + "[" + std::to_string(i) + "]", meta));
      seq->cameras.push_back(camera);
    }
    // Every frame of the run, before the first: its size, tiles and room.
    for (int n = seq->range.first; n <= seq->range.last; ++n)
      VOX_RETURN_IF_ERROR(CheckFrameSize(options, FrameFiles(options, *seq, n).exr,
                                         seq->cameras[size_t(n - 1)], say && n == seq->range.first)
                              .WithContext("frame " + std::to_string(n)));
    return OkStatus();
  }
  VOX_ASSIGN_OR_RETURN(seq->base, JobCamera(options, seq->given.empty() ? nullptr : &seq->given[0],
                                            seq->source, meta));
  // A turntable's frames all have the base's size.
  return CheckFrameSize(options, FrameFiles(options, *seq, seq->range.first).exr, seq->base, say);
}

StatusOr<Camera> FrameCamera(const RenderJobOptions& options, const JobSequence& seq, int number) {
  if (!seq.cameras.empty()) return seq.cameras[size_t(number - 1)];
  if (options.turntable == 0) return seq.base;
  return TurntableCamera(seq.base, options.turntable, seq.centre, number - 1);
}

StatusOr<std::string> SaveCameraText(const RenderJobOptions& options, const JobSequence& seq,
                                     int number) {
  if (options.save_camera_path.empty()) return std::string();
  if (seq.count == 1 || SaveCameraPattern(options)) {
    VOX_ASSIGN_OR_RETURN(const Camera camera, FrameCamera(options, seq, number));
    return camera.ToJson() + "\n";
  }
  if (number != seq.range.last) return std::string();
  std::string text = "[\n";
  for (int n = seq.range.first; n <= seq.range.last; ++n) {
    VOX_ASSIGN_OR_RETURN(const Camera camera, FrameCamera(options, seq, n));
    text += "  " + camera.ToJson() + (n < seq.range.last ? ",\n" : "\n");
  }
  return text + "]\n";
}

}  // namespace vox::job_internal

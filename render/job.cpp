#include "render/job.h"

#include <charconv>
#include <fstream>

#include "core/stopwatch.h"
#include "core/tracer.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/internal/atomic_file.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "storage/store.h"

namespace vox {
Status RunRenderJob(const RenderJobOptions& o) {
  const Stopwatch total;
  Stopwatch phase;
  if (!o.preview_path.empty() && !o.part.whole())
    return InvalidArgumentError(
        "--preview needs the whole image; with --tiles, preview the vox-merge output");
  // Output paths are checked before any work: a bad one fails in a moment,
  // not after the render. The files are written atomically at the end.
  for (const std::string* out : {&o.exr_path, &o.preview_path, &o.stats_path})
    if (!out->empty()) VOX_RETURN_IF_ERROR(CheckOutputPath(*out));
  OpenOptions open;
  open.cache_bytes = o.cache_mb << 20;
  VOX_ASSIGN_OR_RETURN(auto volume, Store::Open(o.store_dir, open));
  const double open_seconds = phase.Lap();
  const StoreMeta& meta = volume->meta();

  Camera camera;
  if (o.camera_path.empty()) {
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    camera = DefaultCamera(lo, hi, o.default_width, o.default_height);
  } else {
    VOX_ASSIGN_OR_RETURN(camera, LoadCamera(o.camera_path));
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    VOX_RETURN_IF_ERROR(CheckCameraDistance(camera, lo, hi).WithContext(o.camera_path));
  }
  Scene scene;
  if (!o.scene_path.empty()) {
    VOX_ASSIGN_OR_RETURN(scene, LoadScene(o.scene_path));
  }

  RenderOptions ro;
  ro.layers = o.layers;
  if (o.single_step && !o.split.empty())
    return InvalidArgumentError("--split and --single-step both choose the split; give one");
  if (o.single_step) {
    ro.n1 = meta.levels;
  } else if (!o.split.empty()) {
    VOX_ASSIGN_OR_RETURN(ro.n1, ParseSplit(o.split, meta.levels));
  }
  VOX_ASSIGN_OR_RETURN(auto renderer, Renderer::Create(volume.get(), camera, scene, ro));
  const double setup_seconds = phase.Lap();

  FrameOptions fo;
  fo.exr_path = o.exr_path;
  fo.threads = o.threads;
  fo.tile_size = o.tile_size;
  fo.part = o.part;
  fo.progress = ChooseProgressMode(o.log, o.quiet);
  fo.progress_out = o.log;
  fo.attrs["vox:store"] = o.store_dir;
  {
    char id[17];
    snprintf(id, sizeof id, "%016llx", (unsigned long long)volume->store_id());
    fo.attrs["vox:storeId"] = id;  // vox-merge refuses parts of different stores
  }
  fo.attrs["vox:grid"] = meta.grid_name;
  fo.attrs["vox:source"] = meta.source_file;
  FrameStats stats;
  VOX_RETURN_IF_ERROR(RenderFrame(*renderer, fo, &stats));
  const double frame_seconds = phase.Lap();
  if (!o.preview_path.empty()) VOX_RETURN_IF_ERROR(WritePngPreview(o.exr_path, o.preview_path));
  const double preview_seconds = phase.Lap();
  if (!o.stats_path.empty()) {
    std::string json = StatsJson(*renderer, stats,
                                 {{"open_seconds", open_seconds},
                                  {"setup_seconds", setup_seconds},
                                  {"frame_seconds", frame_seconds},
                                  {"preview_seconds", preview_seconds},
                                  {"total_seconds", total.Seconds()}});
    VOX_RETURN_IF_ERROR(WriteFileAtomically(o.stats_path, json + "\n"));
  }
  if (!o.quiet) {
    uint64_t total = 0;
    for (int k = 0; k < kNumRayKinds; ++k) total += stats.counters.rays[k];
    fprintf(
        o.log,
        "vox-render: %s (%dx%d, part %s, split %s, passes %s): %.3f s, %llu rays, %.2fM rays/s\n",
        o.exr_path.c_str(), camera.width, camera.height, o.part.ToString().c_str(),
        renderer->SplitString().c_str(), renderer->passes().ToString().c_str(),
        stats.render_seconds, (unsigned long long)total,
        stats.render_seconds > 0 ? total / stats.render_seconds / 1e6 : 0.0);
  }
  return OkStatus();
}

}  // namespace vox

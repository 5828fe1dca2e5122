// vox::RenderJobOptions: what a vox-render job is asked to do (the flags of
// `vox-render`, and the Python module's arguments), read by the job
// (render/job.h) and by the session that opens its stores (render/session.h).
//
// Thread safety: a plain value.
#ifndef VOX_RENDER_JOB_OPTIONS_H_
#define VOX_RENDER_JOB_OPTIONS_H_

#include <cstddef>
#include <cstdio>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "render/exr.h"
#include "render/frame_sequence.h"
#include "render/lod.h"
#include "render/tiles.h"
#include "storage/store.h"

namespace vox {

struct RenderJobOptions {
  std::string store_dir;
  // empty: camera_json, or DefaultCamera over the store's bbox. A camera
  // object, or an array of them: a sequence, a frame per camera.
  std::string camera_path;
  std::string scene_path;   // empty: scene_json, or the default scene
  // cam.json / scene.json text, used when the path is empty; messages name
  // them "camera" and "scene".
  std::string camera_json, scene_json;
  // The outputs of each frame: plain names, or printf frame patterns
  // (out.%04d.exr), which a sequence of more than one frame requires.
  std::string exr_path = "render.exr";  // empty: no EXR (then no preview)
  std::string preview_path;  // empty: none
  std::string stats_path;    // empty: none
  std::string split;         // --split N1+N2 or N1; empty: DefaultFirstStepLevels
  bool single_step = false;
  // The process's memory budget in bytes (--memory-mb); 0: detected
  // (storage/store_budget.h). The brick cache, the threads' pinned bricks
  // and the buffers are sized within it.
  uint64_t memory_bytes = 0;
  size_t cache_mb = 0;  // an explicit brick cache inside the budget; 0: what the budget leaves
  int threads = 0;
  // Read bricks in the background on io_threads threads
  // (OpenOptions::io_threads): the next tiles' first bricks
  // (FrameOptions::prefetch) and, instead of waiting, the bricks a pixel
  // misses (RenderOptions::read_ahead); the scout only without a level of
  // detail in effect. Same pixels either way. Off by default: cold frames
  // wait only for the disk without it, and its threads cost CPU
  // (docs/scale.md, "Cold frames against the disk").
  bool prefetch = false;
  // Read brick records a window of file neighbours at a time
  // (OpenOptions::read_windows); --no-read-windows: each record alone.
  bool read_windows = true;
  // Beam start distances (RenderOptions::beam); --no-beam: off. Same image.
  bool beam = true;
  int io_threads = OpenOptions::kDefaultIoThreads;
  int tile_size = 64;
  // --lod F: level of detail over the store's pyramid (render/lod.h); 0:
  // the exact frame. Unset: kDefaultLodFactor when the store has a pyramid,
  // else exact (the setting in effect goes into --stats and the EXR header).
  std::optional<double> lod;
  // With LOD: coarse silhouettes antialiased from G x G sub-pixel rays
  // (RenderOptions::silhouette_grid); --silhouette-aa G, 0: off.
  int silhouette_grid = kDefaultSilhouetteGrid;
  PartSpec part;
  ImageLayers layers;  // layers.float_color: --float
  std::optional<ExrCompression> compression;  // --compression; default: FrameOptions'
  bool quiet = false;
  int default_width = 1024, default_height = 1024;  // for the default camera
  // --size WxH was given: default_width x default_height is the image size
  // whatever the camera says (flags override the camera JSON).
  bool size_given = false;
  // --view AZIMUTH,ELEVATION in degrees: the camera (the default one, or
  // --cam's projection, field of view, size and up) turned to look at the
  // volume's world-box centre from there, framing the box (OrbitCamera).
  std::optional<std::pair<double, double>> view;
  // --save-cam: the camera used, as cam.json; empty: none. In a sequence: a
  // pattern writes each frame's camera beside its frame, a plain name the
  // array of the rendered frames' cameras with the last frame.
  std::string save_camera_path;
  // --turntable N: N frames, the camera (--cam's, --view's or the default
  // one) turned about its up axis through its look-at point in steps of
  // 360 / N degrees (TurntableCameras). 0: no turntable.
  int turntable = 0;
  // --frames A-B: the frames of the sequence this run renders; unset: all.
  std::optional<FrameRange> frames;
  // --skip-done: a frame whose outputs are already there, complete and
  // verified as this frame of this job (FrameDoneReason, render/frame.h),
  // is not rendered again; others are, replacing what is there.
  bool skip_done = false;
  // Called with each frame's output paths when the frame comes, before
  // its work (vox-render's signal thread removes their temporaries).
  std::function<void(const std::vector<std::string>&)> on_outputs;
  FILE* log = stderr;
  // Keep the image in RenderJobOutput; its bytes are charged to the memory
  // budget before the brick cache is sized. One frame only (--frames N
  // picks one of a sequence).
  bool keep_image = false;
  // --allow-huge: frames over kMaxPixelsUnlessAllowed (render/limits.h).
  bool allow_huge = false;
  // Polled between tiles; an error stops the render, removes the
  // temporaries and is returned (the Python module's KeyboardInterrupt).
  std::function<Status()> interrupted;
};

}  // namespace vox

#endif  // VOX_RENDER_JOB_OPTIONS_H_

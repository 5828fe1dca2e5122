// vox::RunRenderJob: everything `vox-render` does, from options to files:
// chooses the memory budget, opens the store and sizes its cache from the
// budget, reads the camera (or frames the volume) and the scene, renders the image (or one part of it) to EXR, and writes the optional PNG
// preview and --stats JSON. The tool's main only parses flags.
//
// Thread safety: thread-compatible.
#ifndef VOX_RENDER_JOB_H_
#define VOX_RENDER_JOB_H_

#include <cstddef>
#include <cstdio>
#include <optional>
#include <string>

#include "core/status.h"
#include "render/exr.h"
#include "render/tiles.h"

namespace vox {

struct RenderJobOptions {
  std::string store_dir;
  std::string camera_path;  // empty: DefaultCamera over the store's bbox
  std::string scene_path;   // empty: default scene
  std::string exr_path = "render.exr";
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
  // Read the next tiles' bricks ahead (FrameOptions::prefetch). Off by
  // default: on a loaded machine it did not measurably shorten cold frames,
  // and its reads and buffers add to the process's memory.
  bool prefetch = false;
  int tile_size = 64;
  PartSpec part;
  ImageLayers layers;  // layers.float_color: --float
  std::optional<ExrCompression> compression;  // --compression; default: FrameOptions'
  bool quiet = false;
  int default_width = 1024, default_height = 1024;  // for the default camera
  FILE* log = stderr;
};

Status RunRenderJob(const RenderJobOptions& options);

}  // namespace vox

#endif  // VOX_RENDER_JOB_H_

// vox::RunRenderJob: everything `vox-render` does, from options to files:
// chooses the memory budget, opens the store and sizes its cache from the
// budget, reads the camera (or frames the volume) and the scene, renders the image (or one part of it) to EXR, and writes the optional PNG
// preview and --stats JSON. A frame sequence (a cam.json array,
// --turntable N; render/frame_sequence.h) is rendered frame by frame in
// the one process, over the one opened store and its brick cache, each
// frame's outputs published together. The tool's main only parses flags. In-process
// callers (the Python module) may pass the camera and scene as JSON text,
// render without an EXR and keep the image and the stats in memory
// (RenderJobOutput).
//
// Thread safety: thread-compatible.
#ifndef VOX_RENDER_JOB_H_
#define VOX_RENDER_JOB_H_

#include <cstddef>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/util/status.h"
#include "render/job_options.h"
#include "render/session.h"

namespace vox {

// What a job hands back besides its files.
struct RenderJobOutput {
  std::string stats_json;  // the --stats document, written or not
  // With keep_image: the pixels, row-major from the top row, channels
  // interleaved per layer (R G B A; Z; N.X N.Y N.Z; voxel.i voxel.j voxel.k;
  // P.X P.Y P.Z; distance), bit for bit the EXR's. Pixels of other parts
  // (--tiles) stay 0 (Z and distance: +inf).
  int width = 0, height = 0;
  std::vector<float> rgba, z, normal, voxel, position, distance;
};

// `output` may be null. With `session`, the job opens nothing: it renders
// over the session's stores and budget (RenderSession).
Status RunRenderJob(const RenderJobOptions& options, RenderJobOutput* output = nullptr,
                    RenderSession* session = nullptr);

}  // namespace vox

#endif  // VOX_RENDER_JOB_H_

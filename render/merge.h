// vox::MergeParts: assembles the partial EXRs of a split render
// (`vox-render --tiles I/N`) into one complete tiled EXR, tile by tile
// (bounded memory). Refuses parts that do not belong together: different
// image size, tile size, channels, camera, scene, split, store or
// level-of-detail setting; a part
// index given twice (overlap) or missing; a part whose tiles are not all
// present (an unfinished render). Errors name the files.
//
// Thread safety: thread-compatible.
#ifndef VOX_RENDER_MERGE_H_
#define VOX_RENDER_MERGE_H_

#include <string>
#include <vector>

#include "core/util/status.h"

namespace vox {

struct MergeResult {
  int parts = 0;
  int64_t tiles = 0;
  double sum_render_seconds = 0, max_render_seconds = 0;
};

// With a `preview_path`, also the PNG preview (render/exr.h); the EXR and
// the preview are published together once both are written. Before reading
// anything, refuses an output that is a part or the other output
// (core/util/path_identity.h), a bad directory, and a name whose extension is
// not .exr (.png for the preview).
Status MergeParts(const std::vector<std::string>& parts, const std::string& out_path,
                  MergeResult* result = nullptr, const std::string& preview_path = "");

}  // namespace vox

#endif  // VOX_RENDER_MERGE_H_

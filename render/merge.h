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

#include "core/status.h"

namespace vox {

struct MergeResult {
  int parts = 0;
  int64_t tiles = 0;
  double sum_render_seconds = 0, max_render_seconds = 0;
};

Status MergeParts(const std::vector<std::string>& parts, const std::string& out_path,
                  MergeResult* result = nullptr);

}  // namespace vox

#endif  // VOX_RENDER_MERGE_H_

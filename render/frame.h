// vox::RenderFrame: renders all tiles of an image (or of one part, for
// `--tiles I/N`) on worker threads (RunWorkers, core/util/parallel.h),
// writing each tile to the tiled EXR as it finishes, and reports progress and statistics.
//
// Threads pull tiles from one atomic cursor over the Morton tile order, so
// the tiles in flight are neighbours and share their bricks in the cache.
// Each thread has its own tile buffer and counters (merged at the end); the
// memory in use is threads x one tile, whatever the image size.
//
// Thread safety: RenderFrame is thread-compatible (one call per Renderer at a
// time).
#ifndef VOX_RENDER_FRAME_H_
#define VOX_RENDER_FRAME_H_

#include <cstdio>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/util/progress.h"
#include "core/util/status.h"
#include "render/exr.h"
#include "render/limits.h"
#include "render/renderer.h"
#include "render/tiles.h"

namespace vox {

// What vox-render's progress reports show: tiles done, rays per second, the
// cache hit rate and the time left.
struct ProgressSnapshot {
  int64_t tiles_done = 0, tiles_total = 0;
  uint64_t rays = 0;
  uint64_t cache_hits = 0, cache_misses = 0;  // bricks entered without / with paging in
};

// The text of one progress report (without the bar), for the display, tests
// and logs.
std::string ProgressLine(const ProgressSnapshot& s, double elapsed_seconds);

struct FrameOptions {
  std::string exr_path;  // empty: render without writing (benchmarks)
  int threads = 0;       // 0: all cores
  int tile_size = 64;
  PartSpec part;
  ProgressMode progress = ProgressMode::kQuiet;
  FILE* progress_out = stderr;
  ExrAttributes attrs;  // extra header attributes
  // Tile compression; default rle (the cheapest that shrinks a frame: half
  // the size of none, a third of zip's write time), or
  // none for a part of a split render (vox-merge recompresses it as zip).
  std::optional<ExrCompression> compression;
  // Prefetch: when set, a scout thread hands it the bricks the next tiles'
  // primary rays enter first (Renderer::FirstBricks of every
  // prefetch_stride-th pixel) before those tiles render (e.g.
  // Store::Prefetch), so reading them overlaps tracing. The scout stays at
  // most prefetch_tiles tiles ahead, and waits while prefetch_backlog()
  // (bytes read ahead and not yet used) exceeds prefetch_limit.
  std::function<void(std::span<const uint32_t>)> prefetch;
  std::function<uint64_t()> prefetch_backlog;
  uint64_t prefetch_limit = 0;  // 0: no limit besides prefetch_tiles
  int prefetch_tiles = 64;
  // Called with each rendered tile, from the render threads concurrently
  // (after the EXR write); an error stops the frame.
  std::function<Status(const TileRect&, const TileBuffer&)> on_tile;
  // Polled before each tile, from the render threads: an error (the Python
  // caller's KeyboardInterrupt) stops the frame, and the EXR's temporary is
  // removed.
  std::function<Status()> interrupted;
  // Set: the finished EXR stays in its temporary and joins this group, to be
  // published with the run's other outputs (core/util/atomic_file.h).
  OutputGroup* outputs = nullptr;
  int prefetch_stride = 2;  // trace every n-th pixel's primary ray in x and y
};

struct FrameStats {
  RenderCounters counters;
  CacheStats cache_start, cache_end;
  int64_t tiles = 0, tiles_total = 0;
  int threads = 0;
  double render_seconds = 0;  // tiles rendered and written (wall clock)
  double write_seconds = 0;   // time spent in EXR tile writes, summed over threads
  double close_seconds = 0;   // closing the EXR and recording timings
};

// Renders the renderer's camera image (of its volume) as `options` say.
// options.tile_size must be in kMinTileSize..kMaxTileSize.
Status RenderFrame(const Renderer& renderer, const FrameOptions& options, FrameStats* stats);

// The EXR header's string attributes RenderFrame writes for `renderer` and
// `options`: options.attrs, what was rendered (vox:camera, vox:scene,
// vox:split, vox:passes, vox:part, vox:store) and software.
ExrAttributes FrameAttributes(const Renderer& renderer, const FrameOptions& options);

// Why the outputs already at `exr` (and `others`: the preview, the stats,
// the saved camera) are not this frame, rendered as `renderer` and `options`
// would render it, complete; "" when they are: the EXR has every string
// attribute of FrameAttributes with the same value, the renderer's
// channels, and every tile present and readable (VerifyExrTiles); each
// other output exists, is not empty and is no older than the EXR (a frame's
// outputs are published together, the EXR written first).
std::string FrameDoneReason(const Renderer& renderer, const FrameOptions& options,
                            const std::string& exr, const std::vector<std::string>& others);

// The --stats document: rays by kind, DDA moves, transitions, bricks paged
// in, cache hits and misses, timings. `extra_timings` adds named seconds
// (open, setup, preview).
std::string StatsJson(const Renderer& renderer, const FrameStats& stats,
                      const std::vector<std::pair<std::string, double>>& extra_timings);

}  // namespace vox

#endif  // VOX_RENDER_FRAME_H_

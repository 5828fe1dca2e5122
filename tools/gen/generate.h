// vox::gen::Generate: writes a procedural shape (tools/gen/shapes.h) as a
// level-set vox store, or a scalar field as a fog-volume store, brick by
// brick, in memory independent of the grid's size and of the store's voxel
// count.
//
// Bricks are enumerated depth-first in Morton order from the root, descending
// only into octants the shape may occupy (Shape::MayOccupy), so the work and
// the memory follow the occupied bricks, never the grid's volume. A TBB
// pipeline with a bounded number of bricks in flight (2 per thread) fills
// each brick's voxels in parallel (descending inside the brick the same way,
// handing voxels over in Morton order) and adds the bricks to the
// StoreWriter in enumeration order. Besides those bricks, memory holds the
// writer's 56-byte table row per brick (the index it writes at the end).
//
// Reproducible: the same options give a byte-identical store (the store id
// is a hash of the options, bricks are appended in a fixed order). A failed
// or interrupted run leaves no store at the target, and what was there before
// (with force) as it was: StoreWriter builds in a temporary directory and
// replaces the target only when done. An interrupted run's status says which.
//
// Option errors name vox-gen's flags (--size, --levels, --band ...).
// Thread safety: Generate() may be called from any thread; it runs in its own
// TBB arena of `threads` workers.
#ifndef VOX_GEN_GENERATE_H_
#define VOX_GEN_GENERATE_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "core/util/status.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox::gen {

inline constexpr int kMaxSizeLog2 = 20;   // at most 2^20 voxels per axis
inline constexpr int kMaxBrickDepth = 10;  // bricks of at most 1024^3 voxels

struct GenerateOptions {
  std::string shape;           // a name of ShapeNames()
  std::string output;          // the store directory to create
  uint64_t size = 0;           // voxels per axis: a power of two, 2 .. 2^20
  std::string levels = "auto"; // "auto" (32^3 bricks) or "N1+N2" with N1 + N2 = log2(size)
  double band = 3.0;           // narrow-band half-width in voxels, like vdb_tool's width
  int threads = 0;             // 0: all cores
  int zstd_level = 3;
  int normal_bits = 16;
  bool force = false;          // replace an existing store
  bool lod = true;             // also write the level-of-detail pyramid (storage/lod.h)
  // Polled between bricks: when it turns true, Generate stops and writes no store.
  const std::atomic<bool>* cancel = nullptr;
};

// Brick level and depth for `levels` ("auto" or "N1+N2") and a grid of
// 2^size_log2: auto takes bricks of 2^min(5, size_log2 - 1).
struct Levels {
  int brick_level = 0;  // N1: resident levels
  int brick_depth = 0;  // N2: levels inside a brick
};
StatusOr<Levels> ChooseLevels(std::string_view levels, int size_log2);

// Checks the options without writing anything.
Status ValidateOptions(const GenerateOptions& options);

// The canonical form of the options that shape the store's bytes (not the
// output path or the thread count), recorded as its build_options.
std::string CanonicalOptions(const GenerateOptions& options);

struct GenerateStats {
  StoreMeta meta;                  // as written (counts filled in)
  uint64_t voxels = 0;             // occupied voxels written
  uint64_t bricks = 0;             // bricks written
  uint64_t candidate_bricks = 0;   // bricks enumerated (some turn out empty)
  int threads = 0;
  double seconds_bricks = 0, seconds_finish = 0, seconds_total = 0;
  int lod_levels = 0;          // coarse levels written (0: none)
  double seconds_lod = 0;      // building them (part of seconds_finish)
};

// A progress report: the grid's volume decided so far (`done` of `total`,
// in bricks: enumerated, or skipped as empty), and the bricks and voxels
// written. The fraction done / total is the fraction of the grid's Morton
// order behind the generator.
struct GenerateProgressReport {
  uint64_t done = 0, total = 0;
  uint64_t bricks = 0, voxels = 0;
};
// Called from one thread at a time, after each candidate brick in order, and
// once with done == total when every brick is written (then the index and
// the pyramid are finished).
using GenerateProgress = std::function<void(const GenerateProgressReport&)>;

StatusOr<GenerateStats> Generate(const GenerateOptions& options,
                                 const GenerateProgress& progress = nullptr);

}  // namespace vox::gen

#endif  // VOX_GEN_GENERATE_H_

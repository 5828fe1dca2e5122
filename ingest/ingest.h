// vox::Ingest: reads one scalar grid of an OpenVDB file and writes it as a
// vox store (storage/store.h), streaming brick by brick so the peak
// memory stays far below the grid's: the topology is held as compact
// per-leaf records (internal/vdb_topology.h), values decoded on demand.
//
// The occupancy rule: a level set voxel is occupied when it is active and its
// value <= isovalue; a fog volume voxel when it is active and its density >
// threshold. Active tiles count voxel by voxel (they are expanded). Level
// sets keep a normal per voxel (the distance field's central-difference
// gradient in index space), fog volumes the density, and `color_grid` (a
// vec3 grid) an RGB colour sampled at each occupied voxel, and
// `temperature_grid` (a second float or double grid, such as a fire's
// temperature beside its density) a scalar sampled there too.
//
// Placement (levels, origin): see ingest/placement.h. An empty grid (nothing
// occupied) makes a valid empty store.
//
// OpenVDB stays inside this library: nothing here includes it, and no
// OpenVDB exception crosses Ingest(); every failure is a Status naming the
// file (and grid). A failed ingest leaves no store at the target.
//
// Thread safety: Ingest() may be called from any thread; it runs on
// `threads` threads of its own (core/util/parallel.h). A ProgressSink is called from one thread at a
// time.
#ifndef VOX_INGEST_INGEST_H_
#define VOX_INGEST_INGEST_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/util/status.h"
#include "ingest/placement.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox {

struct IngestOptions {
  std::string input;        // the .vdb file
  std::string output;       // the store directory to create
  std::string grid_name;    // empty: the first float or double grid of the file
  std::string levels = "auto";  // "auto" or "N1+N2" (brick_level N1, levels N1 + N2)
  std::optional<double> isovalue;   // level sets; default 0
  std::optional<double> threshold;  // fog volumes; default 0
  std::string color_grid;   // optional Vec3f/Vec3d grid of the same file
  std::string temperature_grid;  // optional float/double grid of the same file (format 1.3)
  int zstd_level = 3;
  int normal_bits = 16;     // per octahedral normal component, 8..16 (WriteOptions::normal_bits)
  int threads = 0;          // 0: all cores
  // Bytes the ingest may hold; 0: the process's limit (its memory cgroup's,
  // or MemAvailable: core/util/memory_budget.h). Bricks in flight are sized
  // to it; a grid whose tables alone exceed half of it is refused.
  uint64_t memory_bytes = 0;
  bool force = false;       // replace an existing store
  // Also write the level-of-detail pyramid (storage/lod.h) before the store
  // is published (vox-ingest --no-lod: false).
  bool lod = true;
  std::string command_line; // recorded in the store's build_options
  // Recorded as the store's source (StoreMeta::source_file); empty: input.
  // An array ingested through a temporary .vdb names the array here.
  std::string source;
  // Resumable (vox-ingest --resume): the bricks are written in
  // `.NAME.resume` beside the output with a journal (WriteOptions::resume_key)
  // that an interrupted, failed or killed run leaves behind; a later run of
  // the same input, options and placement keeps the bricks it verifies,
  // writes the others and builds the pyramid from the whole base store, and
  // the store published is the one an uninterrupted run makes (its id aside).
  bool resume = false;
};

struct IngestStats {
  StoreMeta meta;                   // what was handed to the writer (counts as far as known)
  uint64_t input_bytes = 0;         // size of the .vdb file
  uint64_t active_voxels = 0;       // the grid's active voxels, tiles expanded
  uint64_t leaf_nodes = 0;
  uint64_t active_tiles = 0;        // active tiles (all levels)
  uint64_t occupied_tile_voxels = 0;  // occupied voxels that came from expanded tiles
  uint64_t occupied_voxels = 0;
  uint64_t bricks = 0;
  uint64_t bbox_leaves_read = 0;    // leaves decoded to find the exact occupied bbox
  uint64_t topology_bytes = 0;      // the grid's compact topology and leaf tables
  uint64_t memory_budget = 0;       // bytes the ingest sized itself to (0: no limit known)
  int threads = 0;
  double seconds_open = 0, seconds_bbox = 0, seconds_bricks = 0, seconds_finish = 0;
  double seconds_total = 0;
  int lod_levels = 0;               // coarse levels of the pyramid written (0: none)
  // Finishing the pyramid (part of seconds_finish); built with the bricks,
  // its reduction is part of seconds_bricks.
  double seconds_lod = 0;
};

// Receives progress: phase messages and brick counts. Implementations need
// not be thread-safe (the ingest calls them from one thread at a time).
class ProgressSink {
 public:
  virtual ~ProgressSink() = default;
  virtual void Message(std::string_view line) = 0;
  virtual void Progress(uint64_t bricks_done, uint64_t bricks_total, uint64_t voxels_done) = 0;
  virtual void Done() = 0;
  // Polled at each progress point (a brick; also each base brick the
  // level-of-detail pyramid reads) and before the store is published: true
  // stops the ingest (an Unavailable status, "cancelled"), and the temporary
  // store is removed (the Python module's KeyboardInterrupt).
  virtual bool Cancelled() { return false; }
};

// A bar redrawn in place when `terminal` (stderr is a tty), else a plain line
// every 10%.
std::unique_ptr<ProgressSink> MakeStderrProgress(bool terminal);

// Creates the writer; StoreWriter::Create unless a test substitutes one.
using WriterFactory = std::function<StatusOr<std::unique_ptr<StoreWriter>>(
    const std::string& dir, const StoreMeta& meta, const WriteOptions& options)>;

// Ingests options.input into a store at options.output. `progress` may be null.
StatusOr<IngestStats> Ingest(const IngestOptions& options, ProgressSink* progress = nullptr);

// The same with another writer (tests: fakes, fault injection).
StatusOr<IngestStats> IngestWithWriter(const IngestOptions& options, const WriterFactory& factory,
                                       ProgressSink* progress = nullptr);

}  // namespace vox

#endif  // VOX_INGEST_INGEST_H_

// Brick extraction: the ingest of one float or double grid whose metadata
// ingest.cpp has read and checked. Reads its compact topology, finds the exact
// occupied bbox, places the grid (ingest/placement.h), creates the writer and
// streams the bricks through it (see grid_ingest.cpp for how). Private to
// ingest and its tests.
//
// Thread safety: IngestGrid runs its pipeline in the calling thread's TBB
// arena; one call per grid.
#ifndef VOX_INGEST_INTERNAL_GRID_INGEST_H_
#define VOX_INGEST_INTERNAL_GRID_INGEST_H_

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>

#include "core/util/status.h"
#include "ingest/ingest.h"
#include "ingest/internal/color.h"
#include "ingest/internal/vdb_layout.h"

namespace vox::ingest_internal {

// A name as the ingest's messages quote it: 'name'.
inline std::string Quote(const std::string& s) { return "'" + s + "'"; }

struct Context {
  const IngestOptions& options;
  const WriterFactory& factory;
  ProgressSink* progress;  // may be null
  IngestStats* stats;
  LevelsChoice choice;
  StoreMeta meta;  // source, grid, class, transform, options filled in by the caller
  ColorSource* color = nullptr;
  ColorSource* temperature = nullptr;  // a scalar grid: its value in each component
  uint64_t memory_budget = 0;  // bytes the ingest may hold (0: no limit known)
  uint64_t max_tile_voxels = UINT64_MAX;  // IngestLimits::max_tile_voxels
};

// Ingests `grid` of the file cx.options.input (whose layout is `layout`; a
// FloatGrid, or a DoubleGrid when `double_values`) into a store made by
// cx.factory; fills cx.meta's placement and cx.stats.
Status IngestGrid(const VdbLayout& layout, const VdbLayout::Grid& grid, bool double_values,
                  Context& cx);

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_GRID_INGEST_H_

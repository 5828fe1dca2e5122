// vox::Ingest: options -> store metadata -> the ingest pipeline. See
// ingest.h for the contract. This file checks the options, selects the grid
// (and colour grid) from the file's metadata and fills the store's metadata;
// the pieces it drives each have a file:
//   internal/vdb_layout.h   the .vdb layout check, before OpenVDB reads the file;
//   internal/grid_ingest.h  brick extraction of the chosen grid (topology,
//                           occupied bbox, brick map, the brick pipeline);
//   internal/vdb_topology.h the grid's topology as compact records, streamed
//                           from the file (no OpenVDB tree);
//   internal/voxel_builder.h  one voxel: coordinates, normal or density, colour;
//   internal/leaf_values.h  colour-grid leaf values read without loading them into the tree;
//   internal/color.h        colour sampling from a vec3 grid;
//   placement.h             levels and origin.
#include "core/util/stopwatch.h"
#include "ingest/ingest.h"
#include "ingest/limits.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/points/PointDataGrid.h>

#include "ingest/internal/color.h"
#include "ingest/internal/grid_ingest.h"
#include "ingest/internal/vdb_layout.h"
#include "core/util/memory_budget.h"
#include "core/util/parallel.h"
#include "core/util/path_identity.h"

namespace vox {
namespace {

using ingest_internal::ColorSource;
using ingest_internal::Context;
using ingest_internal::Quote;

// Below this an ingest cannot hold OpenVDB's registries, the threads and one brick.
constexpr uint64_t kMinMemoryBytes = uint64_t(64) << 20;

void InitOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

std::string GridTypeLabel(const openvdb::GridBase& g) {
  return g.valueType() + (g.isType<openvdb::points::PointDataGrid>() ? " (points)" : "");
}

bool IsScalar(const openvdb::GridBase& g) {
  return g.isType<openvdb::FloatGrid>() || g.isType<openvdb::DoubleGrid>();
}

std::string ListGrids(const openvdb::GridPtrVec& grids) {
  std::string s;
  for (const auto& g : grids) {
    if (!s.empty()) s += ", ";
    s += Quote(g->getName()) + " (" + GridTypeLabel(*g) + ", " +
         openvdb::GridBase::gridClassToString(g->getGridClass()) + ")";
  }
  return s.empty() ? "none" : s;
}

std::string FormatDouble(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// The options' own checks, before anything is read.
Status CheckOptions(const IngestOptions& o) {
  if (o.input.empty()) return InvalidArgumentError("no input .vdb file given");
  if (o.output.empty()) return InvalidArgumentError("no output store directory given");
  if (o.zstd_level < 1 || o.zstd_level > 22)
    return InvalidArgumentError("zstd level " + std::to_string(o.zstd_level) + " outside 1..22");
  if (o.normal_bits < 8 || o.normal_bits > 16)
    return InvalidArgumentError("normal precision " + std::to_string(o.normal_bits) +
                                " bits outside 8..16");
  if (o.threads < 0) return InvalidArgumentError("thread count must be >= 0 (0: all cores)");
  if (o.memory_bytes != 0 && o.memory_bytes < kMinMemoryBytes)
    return InvalidArgumentError("memory budget (--memory-mb) of " +
                                std::to_string(o.memory_bytes >> 20) + " MiB is below the " +
                                std::to_string(kMinMemoryBytes >> 20) + " MiB an ingest needs");
  if (o.isovalue && o.threshold)
    return InvalidArgumentError(
        "--isovalue (level sets) and --threshold (fog volumes) exclude each other");
  if (o.isovalue && !std::isfinite(*o.isovalue))
    return InvalidArgumentError("isovalue must be finite");
  if (o.threshold && !std::isfinite(*o.threshold))
    return InvalidArgumentError("threshold must be finite");
  return OkStatus();
}

// The input's size; refuses an input that is not a regular file, and an
// existing target without --force before the (long) read (the writer checks
// again).
StatusOr<uint64_t> CheckInputAndOutput(const IngestOptions& o) {
  struct stat st;
  if (::stat(o.input.c_str(), &st) != 0)
    return errno == ENOENT ? NotFoundError(o.input + ": no such file")
                           : IoError(o.input + ": " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return InvalidArgumentError(o.input + ": not a regular file");
  // The store written (and with --force, the one replaced) must be neither
  // the input nor a directory holding it.
  VOX_RETURN_IF_ERROR(CheckDistinctPaths({{"input", o.input}}, {{"output store", o.output}}));
  if (!o.force && ::access(o.output.c_str(), F_OK) == 0)
    return InvalidArgumentError(o.output + ": already exists; pass --force to replace it");
  return uint64_t(st.st_size);
}

// The grid to ingest (--grid, or the file's first float or double grid),
// refused unless scalar with a linear transform.
StatusOr<openvdb::GridBase::Ptr> ChooseGrid(const IngestOptions& o,
                                            const openvdb::GridPtrVec& grids) {
  openvdb::GridBase::Ptr grid;
  if (!o.grid_name.empty()) {
    for (const auto& g : grids)
      if (g->getName() == o.grid_name) {
        grid = g;
        break;
      }
    if (!grid)
      return NotFoundError(o.input + ": no grid named " + Quote(o.grid_name) +
                           "; the file has: " + ListGrids(grids));
  } else {
    for (const auto& g : grids)
      if (IsScalar(*g)) {
        grid = g;
        break;
      }
    if (!grid)
      return NotFoundError(o.input + ": no float or double grid to ingest; the file has: " +
                           ListGrids(grids));
  }
  const std::string where = "grid " + Quote(grid->getName()) + " in " + o.input;
  if (!IsScalar(*grid))
    return UnsupportedError(where + " holds " + GridTypeLabel(*grid) +
                            " values; vox ingests float and double grids (level sets and fog "
                            "volumes)");
  if (!grid->transform().isLinear())
    return UnsupportedError(where + " has a non-linear (" + grid->transform().mapType() +
                            ") transform; vox needs a linear (affine) one");
  return grid;
}

// The store's metadata from the grid's and the options': source, class and
// occupancy rule, placement, build options. `where` names the grid.
Status DescribeGrid(const IngestOptions& o, const openvdb::GridBase& grid,
                    const std::string& where, StoreMeta* meta) {
  meta->source_file = o.source.empty() ? o.input : o.source;
  meta->grid_name = grid.getName();
  switch (grid.getGridClass()) {
    case openvdb::GRID_LEVEL_SET:
      if (o.threshold)
        return InvalidArgumentError(where + " is a level set; --threshold applies to fog volumes "
                                    "(use --isovalue)");
      meta->grid_class = GridClass::kLevelSet;
      break;
    case openvdb::GRID_FOG_VOLUME:
      if (o.isovalue)
        return InvalidArgumentError(where + " is a fog volume; --isovalue applies to level sets "
                                    "(use --threshold)");
      meta->grid_class = GridClass::kFogVolume;
      break;
    default:
      if (o.threshold) {
        meta->grid_class = GridClass::kFogVolume;
      } else if (o.isovalue) {
        meta->grid_class = GridClass::kLevelSet;
      } else {
        return InvalidArgumentError(
            where + " has grid class " +
            Quote(openvdb::GridBase::gridClassToString(grid.getGridClass())) +
            "; pass --threshold F to read it as a fog volume or --isovalue F as a level set");
      }
  }
  meta->isovalue = o.isovalue.value_or(0.0);
  meta->threshold = o.threshold.value_or(0.0);
  meta->has_normal = meta->grid_class == GridClass::kLevelSet;
  meta->has_density = meta->grid_class == GridClass::kFogVolume;
  const openvdb::math::Mat4d m = grid.transform().baseMap()->getAffineMap()->getMat4();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) meta->index_to_world[i][j] = m(i, j);  // row vectors: same indices
  const openvdb::Vec3d vs = grid.transform().voxelSize();
  meta->voxel_size = std::max({vs[0], vs[1], vs[2]});
  meta->build_options = o.command_line;
  if (meta->build_options.empty()) {
    meta->build_options = "levels=" + o.levels + " zstd_level=" + std::to_string(o.zstd_level);
    if (o.isovalue) meta->build_options += " isovalue=" + FormatDouble(*o.isovalue);
    if (o.threshold) meta->build_options += " threshold=" + FormatDouble(*o.threshold);
    if (!o.color_grid.empty()) meta->build_options += " color=" + o.color_grid;
    if (!o.temperature_grid.empty()) meta->build_options += " temperature=" + o.temperature_grid;
    if (o.normal_bits != 16) meta->build_options += " normal_bits=" + std::to_string(o.normal_bits);
  }
  return OkStatus();
}

// The colour grid (--color; null without it), refused unless a vec3 grid
// with a linear transform.
StatusOr<openvdb::GridBase::Ptr> ChooseColorGrid(const IngestOptions& o,
                                                 const openvdb::GridPtrVec& grids) {
  if (o.color_grid.empty()) return openvdb::GridBase::Ptr();
  openvdb::GridBase::Ptr color;
  for (const auto& g : grids)
    if (g->getName() == o.color_grid) color = g;
  if (!color)
    return NotFoundError(o.input + ": no colour grid named " + Quote(o.color_grid) +
                         "; the file has: " + ListGrids(grids));
  const std::string where = "colour grid " + Quote(o.color_grid) + " in " + o.input;
  if (!color->isType<openvdb::Vec3fGrid>() && !color->isType<openvdb::Vec3dGrid>())
    return UnsupportedError(where + " holds " + GridTypeLabel(*color) +
                            " values; a colour grid holds vec3s or vec3d");
  if (!color->transform().isLinear()) return UnsupportedError(where + " has a non-linear transform");
  return color;
}

// The temperature grid (--temperature; null without it), refused unless a
// float or double grid with a linear transform other than the main grid.
StatusOr<openvdb::GridBase::Ptr> ChooseTemperatureGrid(const IngestOptions& o,
                                                       const openvdb::GridPtrVec& grids,
                                                       const std::string& main_name) {
  if (o.temperature_grid.empty()) return openvdb::GridBase::Ptr();
  openvdb::GridBase::Ptr t;
  for (const auto& g : grids)
    if (g->getName() == o.temperature_grid) t = g;
  if (!t)
    return NotFoundError(o.input + ": no temperature grid named " + Quote(o.temperature_grid) +
                         "; the file has: " + ListGrids(grids));
  const std::string where = "temperature grid " + Quote(o.temperature_grid) + " in " + o.input;
  if (o.temperature_grid == main_name)
    return InvalidArgumentError(where + " is the grid being ingested; name another grid");
  if (!t->isType<openvdb::FloatGrid>() && !t->isType<openvdb::DoubleGrid>())
    return UnsupportedError(where + " holds " + GridTypeLabel(*t) +
                            " values; a temperature grid holds floats or doubles");
  if (!t->transform().isLinear()) return UnsupportedError(where + " has a non-linear transform");
  return t;
}

// Where the grid `name` lies in the file (its offsets), which the streaming
// reader needs.
StatusOr<const ingest_internal::VdbLayout::Grid*> FindGridLayout(
    const ingest_internal::VdbLayout& layout, const std::string& name, const std::string& where) {
  for (const auto& g : layout.grids)
    if (g.name == name) return &g;
  return UnsupportedError(where + ": the file has no grid offsets (an OpenVDB stream or a "
                          "file older than format 2.1.2); re-save it as a .vdb file");
}

// The memory the ingest may hold: --memory-mb, or what the process may use.
StatusOr<uint64_t> MemoryBudget(const IngestOptions& o) {
  if (o.memory_bytes != 0) return o.memory_bytes;
  VOX_ASSIGN_OR_RETURN(MemoryLimit limit, DetectMemoryLimit());
  return limit.bytes;
}

StatusOr<IngestStats> IngestImpl(const IngestOptions& o, const IngestLimits& limits,
                                 const WriterFactory& factory, ProgressSink* progress) {
  const Stopwatch t_start;
  IngestStats stats;
  VOX_RETURN_IF_ERROR(CheckOptions(o));
  VOX_ASSIGN_OR_RETURN(LevelsChoice choice, ParseLevels(o.levels));
  VOX_ASSIGN_OR_RETURN(stats.input_bytes, CheckInputAndOutput(o));

  // Open the file and choose the grids.
  Stopwatch t0;
  VOX_ASSIGN_OR_RETURN(ingest_internal::VdbLayout layout, ingest_internal::ReadVdbLayout(o.input));
  InitOpenVdb();
  openvdb::io::File file(o.input);
  file.setCopyMaxBytes(0);  // read the file in place, no private copy
  try {
    file.open(/*delayLoad=*/true);
  } catch (const openvdb::Exception& e) {
    return CorruptionError(o.input + ": not a readable OpenVDB file (" + e.what() + ")");
  }
  openvdb::GridPtrVecPtr grids = file.readAllGridMetadata();
  VOX_ASSIGN_OR_RETURN(const openvdb::GridBase::Ptr meta_grid, ChooseGrid(o, *grids));
  const std::string name = meta_grid->getName();
  const std::string where = "grid " + Quote(name) + " in " + o.input;
  Context cx{o, factory, progress, &stats, choice, StoreMeta{}, nullptr};
  VOX_RETURN_IF_ERROR(DescribeGrid(o, *meta_grid, where, &cx.meta));
  VOX_ASSIGN_OR_RETURN(const openvdb::GridBase::Ptr color_meta, ChooseColorGrid(o, *grids));
  VOX_ASSIGN_OR_RETURN(const openvdb::GridBase::Ptr temperature_meta,
                       ChooseTemperatureGrid(o, *grids, name));
  VOX_ASSIGN_OR_RETURN(const ingest_internal::VdbLayout::Grid* grid_layout,
                       FindGridLayout(layout, name, where));
  VOX_ASSIGN_OR_RETURN(const uint64_t budget, MemoryBudget(o));
  cx.memory_budget = budget;
  cx.max_tile_voxels = limits.max_tile_voxels;
  stats.memory_budget = budget;

  // Read the colour grid whole; the grid itself is streamed by IngestGrid.
  if (progress) progress->Message("reading the topology of " + where);
  std::unique_ptr<ColorSource> color;
  if (color_meta) {
    color = ingest_internal::NewColorSource(file.readGrid(o.color_grid), meta_grid->transform());
    if (!color) return InternalError("colour grid " + Quote(o.color_grid) + " in " + o.input +
                                     ": grid type changed between metadata and read");
    cx.meta.has_color = true;
    cx.color = color.get();
  }
  std::unique_ptr<ColorSource> temperature;
  if (temperature_meta) {
    temperature = ingest_internal::NewScalarSource(file.readGrid(o.temperature_grid),
                                                   meta_grid->transform());
    if (!temperature)
      return InternalError("temperature grid " + Quote(o.temperature_grid) + " in " + o.input +
                           ": grid type changed between metadata and read");
    cx.meta.has_temperature = true;
    cx.temperature = temperature.get();
  }
  stats.seconds_open = t0.Seconds();

  // Ingest on the threads asked for.
  const int threads = o.threads > 0 ? o.threads : DefaultThreads();
  stats.threads = threads;
  Status s;
  const bool double_values = meta_grid->isType<openvdb::DoubleGrid>();
  WithThreadLimit(threads, [&] {
    s = ingest_internal::IngestGrid(layout, *grid_layout, double_values, cx);
  });
  if (!s.ok()) return s;
  stats.seconds_total = t_start.Seconds();
  if (progress) progress->Done();
  return stats;
}

}  // namespace

StatusOr<IngestStats> IngestWithWriter(const IngestOptions& options, const IngestLimits& limits,
                                       const WriterFactory& factory, ProgressSink* progress) {
  try {
    return IngestImpl(options, limits, factory, progress);
  } catch (const openvdb::Exception& e) {
    return CorruptionError(options.input + ": OpenVDB cannot read it: " + e.what());
  } catch (const std::bad_alloc&) {
    return ResourceExhaustedError("out of memory ingesting " + options.input +
                                  " (a corrupt file can make OpenVDB ask for huge allocations)");
  } catch (const std::exception& e) {
    return InternalError("ingesting " + options.input + ": " + e.what());
  }
}


StatusOr<IngestStats> IngestWithWriter(const IngestOptions& options, const WriterFactory& factory,
                                       ProgressSink* progress) {
  return IngestWithWriter(options, IngestLimits{}, factory, progress);
}

}  // namespace vox

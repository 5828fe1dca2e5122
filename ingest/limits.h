// vox::IngestLimits: bounds on what a valid but hostile grid may make the
// ingest do, and the Ingest overload that applies them. Plain values;
// thread-safe.
#ifndef VOX_INGEST_LIMITS_H_
#define VOX_INGEST_LIMITS_H_

#include <cstdint>

#include "core/util/status.h"
#include "ingest/ingest.h"

namespace vox {

struct IngestLimits {
  // vox stores voxels, so an active tile becomes every voxel it covers: a
  // grid whose occupied tiles cover more than this is refused before any
  // brick is written (vox-ingest --max-voxels). One root tile of a float
  // grid covers 4096^3 = 6.9e10 voxels.
  static constexpr uint64_t kDefaultMaxTileVoxels = uint64_t(10000000000);  // 1e10
  uint64_t max_tile_voxels = kDefaultMaxTileVoxels;
};

// Ingest and IngestWithWriter (ingest.h) under `limits`; the overloads
// without limits use the defaults.
StatusOr<IngestStats> Ingest(const IngestOptions& options, const IngestLimits& limits,
                             ProgressSink* progress = nullptr);
StatusOr<IngestStats> IngestWithWriter(const IngestOptions& options, const IngestLimits& limits,
                                       const WriterFactory& factory,
                                       ProgressSink* progress = nullptr);

}  // namespace vox

#endif  // VOX_INGEST_LIMITS_H_

// vox::InspectStore: a store's metadata and statistics (counts, sizes,
// compression, brick size histogram), optionally checking every brick, for
// vox-info and benchmarks. Thread-compatible; InspectStore is thread-safe.
#ifndef VOX_STORAGE_STORE_INFO_H_
#define VOX_STORAGE_STORE_INFO_H_

#include <cstdint>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "storage/store.h"

namespace vox {

struct StoreInfo {
  std::string dir;
  StoreMeta meta;
  int format_major = 0, format_minor = 0;
  uint64_t index_file_bytes = 0, brick_file_bytes = 0;
  uint64_t top_bytes = 0;        // resident top cells
  uint64_t resident_bytes = 0;   // Store::resident_bytes(): top, top payloads, brick table
  uint64_t brick_cells = 0;      // cells in all bricks
  uint64_t stored_bytes = 0;     // brick records on disk (frames + trailers)
  uint64_t raw_bytes = 0;        // bricks decompressed (masks + attributes)
  uint64_t decoded_bytes = 0;    // bricks as the cache holds them (cells + attributes)
  uint64_t min_brick_voxels = 0, max_brick_voxels = 0;
  // histogram[k]: bricks whose stored size is in [2^k, 2^(k+1)) bytes.
  std::vector<uint64_t> stored_size_histogram;
  bool verified = false;  // every brick decompressed and checked
  // With verify_bricks and a pyramid (lod/): its levels, every one opened
  // (a missing or foreign level fails) and every brick checked.
  int lod_levels_verified = 0;
};

// Opens the store at `dir` and gathers its statistics; with verify_bricks,
// decompresses and checks every brick (through a cache of cache_bytes), the
// pyramid's levels' (lod/N/) included.
StatusOr<StoreInfo> InspectStore(const std::string& dir, bool verify_bricks,
                                 size_t cache_bytes = size_t(64) << 20);

// A human-readable report, in the manner of vdb_print.
std::string FormatStoreInfo(const StoreInfo& info);

}  // namespace vox

#endif  // VOX_STORAGE_STORE_INFO_H_

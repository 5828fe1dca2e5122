// The .vdb file's outer layout, checked before OpenVDB reads it: OpenVDB
// trusts the lengths it reads, so a truncated file can make it allocate
// gigabytes for a garbage string. Private to ingest and its tests.
//
// Thread safety: stateless; may be called from any thread.
#ifndef VOX_INGEST_INTERNAL_VDB_LAYOUT_H_
#define VOX_INGEST_INTERNAL_VDB_LAYOUT_H_

#include <cstdint>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace vox::ingest_internal {

// What the walk finds: the versions and each grid's byte ranges.
struct VdbLayout {
  uint32_t file_version = 0;
  uint32_t library_major = 0, library_minor = 0;
  bool has_offsets = false;  // false: pre-2.1.1 or a stream; grids below are empty
  struct Grid {
    std::string name;      // without the uniqueness suffix
    bool instance = false; // shares another grid's tree
    uint64_t grid_pos = 0, block_pos = 0, end_pos = 0;
  };
  std::vector<Grid> grids;
};

// Walks the header, the file metadata and the grid descriptors (each with
// its grid's [start, end) offsets) of the file at `path` and checks every
// length and offset against the file size. Grid contents are left to
// OpenVDB, as are files older than format 2.1.1 and streams without grid
// offsets. Errors name the file and what runs past its end.
Status CheckVdbLayout(const std::string& path);
// The same, returning what it read.
StatusOr<VdbLayout> ReadVdbLayout(const std::string& path);

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_VDB_LAYOUT_H_

// The .vdb file's outer layout, checked before OpenVDB reads it: OpenVDB
// trusts the lengths it reads, so a truncated file can make it allocate
// gigabytes for a garbage string. Private to ingest and its tests.
//
// Thread safety: stateless; may be called from any thread.
#ifndef VOX_INGEST_INTERNAL_VDB_LAYOUT_H_
#define VOX_INGEST_INTERNAL_VDB_LAYOUT_H_

#include <string>

#include "core/status.h"

namespace vox::ingest_internal {

// Walks the header, the file metadata and the grid descriptors (each with
// its grid's [start, end) offsets) of the file at `path` and checks every
// length and offset against the file size. Grid contents are left to
// OpenVDB, as are files older than format 2.1.1 and streams without grid
// offsets. Errors name the file and what runs past its end.
Status CheckVdbLayout(const std::string& path);

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_VDB_LAYOUT_H_

// Cross-checks of a store's metadata (storage/meta.h), which a valid CRC
// does not make right: an edited bbox, origin or voxel size would render a
// wrong image with exit 0. Run at every open, on the metadata block alone
// (CheckMetaFields, from DecodeMeta) and against the resident top
// (CheckMetaAgainstTop, from Store's Load): the top's brick-level cells are
// the occupied bricks, so the brick table is not read for this.
//
// Thread safety: stateless; thread-safe.
#ifndef VOX_STORAGE_META_CHECK_H_
#define VOX_STORAGE_META_CHECK_H_

#include <cstdint>
#include <span>
#include <string>

#include "core/octree.h"
#include "core/util/status.h"
#include "storage/meta.h"

namespace vox {

// The largest origin component magnitude a store may have: 2^52, so that
// origin + 2^kMaxLevels never overflows and index coordinates stay exact in
// a double (OpenVDB's own coordinates are 32-bit).
inline constexpr int64_t kMaxStoreOrigin = int64_t(1) << 52;

// Corruption naming `path` unless: the voxel size is finite and > 0, the
// index-to-world map is finite, every origin component lies within
// +-kMaxStoreOrigin, and a base store's bbox (when it has voxels) is
// ordered and inside its grid [origin, origin + 2^levels).
Status CheckMetaFields(const StoreMeta& m, const std::string& path);

// Corruption naming `path` unless a base store's bbox agrees with the
// occupied cells of the top's last level (bricks, or voxels of a top-only
// store) in level order (`top`): every occupied cell meets the bbox and
// together they cover it. Pyramid levels keep the base's bbox and are not
// compared.
Status CheckMetaAgainstTop(const StoreMeta& m, std::span<const CompactCell> top,
                           const std::string& path);

}  // namespace vox

#endif  // VOX_STORAGE_META_CHECK_H_

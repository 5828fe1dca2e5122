// The size limits of vox's images: the largest image side, the tile sizes
// vox-render writes and the most tiles an image may have. The camera, the
// frame loop, the tile layout and the EXR readers (which refuse headers
// beyond them) share these. Constants; thread-safe.
#ifndef VOX_RENDER_LIMITS_H_
#define VOX_RENDER_LIMITS_H_

#include <cstdint>

namespace vox {

// Largest image side vox-render accepts.
inline constexpr int kMaxImageSide = 1 << 20;

// Tile sides vox-render writes (--tile-size).
inline constexpr int kMinTileSize = 8, kMaxTileSize = 4096;

// The most tiles an image may have: the tile order (and the EXR's tile
// offset table) are held in memory, about 32 bytes a tile. 2^22 tiles is
// 131072 x 131072 pixels in 64-pixel tiles; larger tiles allow larger images.
inline constexpr int64_t kMaxTiles = int64_t(1) << 22;

// The most pixels vox-render renders without --allow-huge: 2^28, a 16384 x
// 16384 frame (about 3 GiB as an uncompressed EXR with every layer). A
// larger one is refused before the store is read, saying its size.
inline constexpr int64_t kMaxPixelsUnlessAllowed = int64_t(1) << 28;

}  // namespace vox

#endif  // VOX_RENDER_LIMITS_H_

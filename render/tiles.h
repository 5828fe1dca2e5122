// vox::TileLayout: how an image is cut into T x T tiles, the order they are
// rendered in (Morton order over the tile grid, so neighbouring tiles, which
// see neighbouring bricks, run close together in time), and which tiles
// belong to part I of N (`--tiles I/N`: a contiguous run of that order, so
// each part is a compact region of the image).
//
// Thread safety: immutable value; thread-safe.
#ifndef VOX_RENDER_TILES_H_
#define VOX_RENDER_TILES_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"
#include "render/limits.h"

namespace vox {

struct TileRect {
  int tx = 0, ty = 0;  // tile coordinates
  int x0 = 0, y0 = 0;  // first pixel
  int w = 0, h = 0;    // size (smaller at the right and bottom edges)
};

// A part of a split render: index in 1..count.
struct PartSpec {
  int index = 1, count = 1;
  bool whole() const { return count == 1; }
  std::string ToString() const { return std::to_string(index) + "/" + std::to_string(count); }
};

// OkStatus when a width x height image cut into tile x tile tiles has at most
// kMaxTiles (render/limits.h) tiles (and all are positive); otherwise an error naming the limit.
Status CheckTileCount(int width, int height, int tile);

// Parses "I/N" with 1 <= I <= N.
StatusOr<PartSpec> ParsePartSpec(std::string_view text);

// A warning when `part` cuts a width x height image of tile x tile tiles
// into more parts than it has tiles (some parts, maybe this one, are
// empty), saying how many tiles it has and which this part renders; "" otherwise.
std::string PartCountWarning(int width, int height, int tile, const PartSpec& part);

class TileLayout {
 public:
  // REQUIRES: width, height, tile >= 1 and CheckTileCount(width, height, tile).
  TileLayout(int width, int height, int tile);

  int width() const { return width_; }
  int height() const { return height_; }
  int tile_size() const { return tile_; }
  int tiles_x() const { return nx_; }
  int tiles_y() const { return ny_; }
  int64_t num_tiles() const { return int64_t(nx_) * ny_; }
  TileRect Rect(int tx, int ty) const;

  // All tiles in render order.
  const std::vector<TileRect>& order() const { return order_; }
  // The tiles of `part`, in render order: order()[begin, end).
  void PartRange(const PartSpec& part, int64_t* begin, int64_t* end) const;

 private:
  int width_, height_, tile_, nx_, ny_;
  std::vector<TileRect> order_;
};

}  // namespace vox

#endif  // VOX_RENDER_TILES_H_

#include "render/tiles.h"

#include <algorithm>
#include <charconv>

namespace vox {
namespace {

uint64_t Spread(uint32_t v) {
  uint64_t x = v;
  x = (x | (x << 16)) & 0x0000ffff0000ffffull;
  x = (x | (x << 8)) & 0x00ff00ff00ff00ffull;
  x = (x | (x << 4)) & 0x0f0f0f0f0f0f0f0full;
  x = (x | (x << 2)) & 0x3333333333333333ull;
  x = (x | (x << 1)) & 0x5555555555555555ull;
  return x;
}

}  // namespace

Status CheckTileCount(int width, int height, int tile) {
  if (width < 1 || height < 1 || tile < 1)
    return InvalidArgumentError("image " + std::to_string(width) + "x" + std::to_string(height) +
                                " in tiles of " + std::to_string(tile) +
                                ": sizes must be positive");
  const int64_t n = ((int64_t(width) + tile - 1) / tile) * ((int64_t(height) + tile - 1) / tile);
  if (n > kMaxTiles)
    return InvalidArgumentError(
        "image " + std::to_string(width) + "x" + std::to_string(height) + " in " +
        std::to_string(tile) + "-pixel tiles has " + std::to_string(n) + " tiles, more than the " +
        std::to_string(kMaxTiles) + " allowed; use a larger --tile-size or a smaller image");
  return OkStatus();
}

StatusOr<PartSpec> ParsePartSpec(std::string_view text) {
  auto slash = text.find('/');
  auto bad = [&]() {
    return InvalidArgumentError("--tiles '" + std::string(text) +
                                "': expected I/N with 1 <= I <= N (e.g. 3/8)");
  };
  if (slash == std::string_view::npos) return bad();
  PartSpec p;
  auto a = text.substr(0, slash), b = text.substr(slash + 1);
  auto r1 = std::from_chars(a.data(), a.data() + a.size(), p.index);
  auto r2 = std::from_chars(b.data(), b.data() + b.size(), p.count);
  if (a.empty() || b.empty() || r1.ec != std::errc() || r1.ptr != a.data() + a.size() ||
      r2.ec != std::errc() || r2.ptr != b.data() + b.size())
    return bad();
  if (p.count < 1 || p.index < 1 || p.index > p.count) return bad();
  return p;
}

std::string PartCountWarning(int width, int height, int tile, const PartSpec& part) {
  if (width < 1 || height < 1 || tile < 1) return "";
  const int64_t tiles = ((int64_t(width) + tile - 1) / tile) * ((int64_t(height) + tile - 1) / tile);
  if (part.count <= tiles) return "";
  const int64_t begin = tiles * (part.index - 1) / part.count, end = tiles * part.index / part.count;
  return "--tiles " + part.ToString() + ": the " + std::to_string(width) + "x" +
         std::to_string(height) + " image has only " + std::to_string(tiles) + " tiles of " +
         std::to_string(tile) + " pixels, fewer than the " + std::to_string(part.count) +
         " parts, so some parts are empty; this part renders " + std::to_string(end - begin) +
         (end - begin == 1 ? " tile" : " tiles");
}

TileLayout::TileLayout(int width, int height, int tile)
    : width_(width), height_(height), tile_(tile) {
  nx_ = (width + tile - 1) / tile;
  ny_ = (height + tile - 1) / tile;
  order_.reserve(size_t(nx_) * ny_);
  for (int ty = 0; ty < ny_; ++ty)
    for (int tx = 0; tx < nx_; ++tx) order_.push_back(Rect(tx, ty));
  std::sort(order_.begin(), order_.end(), [](const TileRect& a, const TileRect& b) {
    uint64_t ka = Spread(uint32_t(a.tx)) | (Spread(uint32_t(a.ty)) << 1);
    uint64_t kb = Spread(uint32_t(b.tx)) | (Spread(uint32_t(b.ty)) << 1);
    return ka < kb;
  });
}

TileRect TileLayout::Rect(int tx, int ty) const {
  TileRect r;
  r.tx = tx;
  r.ty = ty;
  r.x0 = tx * tile_;
  r.y0 = ty * tile_;
  r.w = std::min(tile_, width_ - r.x0);
  r.h = std::min(tile_, height_ - r.y0);
  return r;
}

void TileLayout::PartRange(const PartSpec& part, int64_t* begin, int64_t* end) const {
  const int64_t n = num_tiles();
  *begin = n * (part.index - 1) / part.count;
  *end = n * part.index / part.count;
}

}  // namespace vox

// Renders a whole image into memory through Renderer::RenderTile, for tests.
#ifndef VOX_TESTS_RENDER_RENDER_UTIL_H_
#define VOX_TESTS_RENDER_RENDER_UTIL_H_

#include <map>
#include <string>
#include <vector>

#include "render/renderer.h"
#include "render/tiles.h"

namespace vox::testing {

struct Image {
  int width = 0, height = 0;
  std::map<std::string, std::vector<float>> ch;
  float at(const std::string& c, int x, int y) const { return ch.at(c)[size_t(y) * width + x]; }
};

inline Status RenderToMemory(const Renderer& r, Image* img, RenderCounters* counters,
                             int tile = 16) {
  const int w = r.camera().width, h = r.camera().height;
  img->width = w;
  img->height = h;
  TileLayout layout(w, h, tile);
  TileBuffer buf;
  buf.Allocate(tile, r.layers());
  for (int c = 0; c < kNumChannels; ++c)
    if (r.layers().Has(c)) img->ch[ChannelName(c)].assign(size_t(w) * h, 0.0f);
  for (const TileRect& rect : layout.order()) {
    VOX_RETURN_IF_ERROR(r.RenderTile(rect, &buf, counters));
    for (int c = 0; c < kNumChannels; ++c) {
      if (!r.layers().Has(c)) continue;
      auto& dst = img->ch[ChannelName(c)];
      for (int y = 0; y < rect.h; ++y)
        for (int x = 0; x < rect.w; ++x)
          dst[size_t(rect.y0 + y) * w + rect.x0 + x] = *buf.at(c, x, y);
    }
  }
  return OkStatus();
}

}  // namespace vox::testing

#endif  // VOX_TESTS_RENDER_RENDER_UTIL_H_

// Fuzz target: the text parsers of user input. Byte 0 chooses camera JSON
// (cam.json), scene JSON (scene.json) or ray lines (vox-probe's input, one
// per line); the rest is the text. A parsed camera is also asked for its
// corner rays. Any input must give a Status, never a crash.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/ray_text.h"
#include "render/camera.h"
#include "render/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  switch (data[0] % 3) {
    case 0: {
      auto cam = vox::ParseCamera(text, "fuzz/cam.json");
      if (cam.ok()) {
        const vox::WorldRay r = cam->PixelRay(0.5, 0.5);
        if (!(r.dir.x == r.dir.x)) __builtin_trap();  // a finalized camera gives finite rays
      }
      break;
    }
    case 1:
      (void)vox::ParseScene(text, "fuzz/scene.json");
      break;
    default: {
      size_t start = 0;
      while (start <= text.size()) {
        size_t end = text.find('\n', start);
        if (end == std::string_view::npos) end = text.size();
        (void)vox::ParseRayLine(text.substr(start, end - start));
        start = end + 1;
      }
    }
  }
  return 0;
}

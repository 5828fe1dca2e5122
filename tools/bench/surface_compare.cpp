// vox-surface-compare: compares two renders of a surface, either EXR layout
// (vox's tiled files, vdb_render's scanline ones): the masks (alpha > 1/2;
// the reference's from REF_MASK.exr's R > 1/2 when given: vdb_render's alpha
// is 1 everywhere, its -shader matte image is white where it hits), their
// IoU, and the root mean square RGB difference (linear) over the pixels both
// masks cover, with the count of such pixels. Prints one JSON line.
// tools/bench/surface_compare.sh runs it on the bunny close-up.
//   vox-surface-compare REF.exr TEST.exr [REF_MASK.exr]
#include <ImfArray.h>
#include <ImfRgbaFile.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <string>

namespace {

struct Image {
  int w = 0, h = 0;
  Imf::Array2D<Imf::Rgba> px;
};

bool Read(const char* path, Image* img, std::string* error) {
  try {
    Imf::RgbaInputFile in(path);
    const Imath::Box2i dw = in.dataWindow();
    img->w = dw.max.x - dw.min.x + 1;
    img->h = dw.max.y - dw.min.y + 1;
    img->px.resizeErase(img->h, img->w);
    in.setFrameBuffer(&img->px[0][0] - dw.min.x - dw.min.y * img->w, 1, size_t(img->w));
    in.readPixels(dw.min.y, dw.max.y);
    return true;
  } catch (const std::exception& e) {
    *error = std::string(path) + ": " + e.what();
    return false;
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3 && argc != 4) {
    std::fprintf(stderr, "usage: vox-surface-compare REF.exr TEST.exr [REF_MASK.exr]\n");
    return 2;
  }
  Image a, b, m;
  std::string error;
  if (!Read(argv[1], &a, &error) || !Read(argv[2], &b, &error) ||
      (argc == 4 && !Read(argv[3], &m, &error))) {
    std::fprintf(stderr, "vox-surface-compare: %s\n", error.c_str());
    return 1;
  }
  if (a.w != b.w || a.h != b.h || (argc == 4 && (m.w != a.w || m.h != a.h))) {
    std::fprintf(stderr, "vox-surface-compare: image sizes differ\n");
    return 1;
  }
  unsigned long long inter = 0, uni = 0, ref_px = 0, test_px = 0;
  double sq = 0;
  for (int y = 0; y < a.h; ++y)
    for (int x = 0; x < a.w; ++x) {
      const Imf::Rgba& p = a.px[y][x];
      const Imf::Rgba& q = b.px[y][x];
      const bool ia = argc == 4 ? float(m.px[y][x].r) > 0.5f : float(p.a) > 0.5f;
      const bool ib = float(q.a) > 0.5f;
      ref_px += ia;
      test_px += ib;
      uni += ia || ib;
      if (!(ia && ib)) continue;
      ++inter;
      const double d[3] = {double(p.r) - double(q.r), double(p.g) - double(q.g),
                           double(p.b) - double(q.b)};
      sq += d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    }
  std::printf(
      "{\"ref_pixels\": %llu, \"test_pixels\": %llu, \"both_pixels\": %llu, \"mask_iou\": %.6f, "
      "\"rmse_rgb_both\": %.6f}\n",
      ref_px, test_px, inter, uni ? double(inter) / double(uni) : 1.0,
      inter ? std::sqrt(sq / (3.0 * double(inter))) : 0.0);
  return 0;
}

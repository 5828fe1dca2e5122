// vox-lod-compare: compares a render against a full-resolution reference
// (docs/lod.md): mean absolute RGB difference (linear values, and 8-bit
// sRGB levels) over all pixels and over the pixels either image covers,
// the root mean square RGB and alpha differences (linear), the silhouette
// pixels wrong (alpha differs by more than 1/2: a pixel a coverage test
// would call covered in one image and not in the other) and the silhouette
// IoU (alpha > 0); optionally writes a PNG of a crop of
// both side by side (reference left), magnified, to show moire.
//   vox-lod-compare REF.exr TEST.exr [--crop X,Y,W,H --png OUT.png [--zoom Z]]
#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "render/exr.h"

namespace {

int Fail(const std::string& m) {
  std::fprintf(stderr, "vox-lod-compare: %s\n", m.c_str());
  return 2;
}

double ToSrgb8(double v) {
  v = std::clamp(v, 0.0, 1.0);
  const double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
  return std::round(s * 255.0);
}

bool WritePng(const std::string& path, int w, int h, const std::vector<unsigned char>& rgb) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    return false;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, png_uint_32(w), png_uint_32(h), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < h; ++y)
    png_write_row(png, const_cast<unsigned char*>(rgb.data() + size_t(y) * w * 3));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return std::fclose(f) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return Fail("usage: vox-lod-compare REF.exr TEST.exr [--crop X,Y,W,H --png OUT.png [--zoom Z]]");
  int cx = 0, cy = 0, cw = 0, ch = 0, zoom = 2;
  std::string png;
  for (int i = 3; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--crop" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%d,%d,%d,%d", &cx, &cy, &cw, &ch) != 4 || cw <= 0 || ch <= 0)
        return Fail("--crop X,Y,W,H");
    } else if (a == "--png" && i + 1 < argc) {
      png = argv[++i];
    } else if (a == "--zoom" && i + 1 < argc) {
      zoom = std::max(1, std::atoi(argv[++i]));
    } else {
      return Fail("unknown argument " + a);
    }
  }
  auto ra = vox::ReadExr(argv[1]);
  if (!ra.ok()) return Fail(ra.status().ToString());
  auto rb = vox::ReadExr(argv[2]);
  if (!rb.ok()) return Fail(rb.status().ToString());
  const int w = ra->info.width, h = ra->info.height;
  if (rb->info.width != w || rb->info.height != h) return Fail("image sizes differ");
  const auto& A = ra->pixels;
  const auto& B = rb->pixels;
  double lin = 0, srgb = 0, lin_cov = 0, srgb_cov = 0, sq_rgb = 0, sq_alpha = 0;
  uint64_t inter = 0, uni = 0, wrong = 0, n = uint64_t(w) * h;
  for (size_t i = 0; i < n; ++i) {
    double dl = 0, ds = 0;
    for (const char* c : {"R", "G", "B"}) {
      const double a = A.at(c)[i], b = B.at(c)[i];
      dl += std::fabs(a - b);
      ds += std::fabs(ToSrgb8(a) - ToSrgb8(b));
      sq_rgb += (a - b) * (a - b);
    }
    const double da = double(A.at("A")[i]) - double(B.at("A")[i]);
    sq_alpha += da * da;
    wrong += std::fabs(da) > 0.5;
    lin += dl / 3;
    srgb += ds / 3;
    const bool ia = A.at("A")[i] > 0, ib = B.at("A")[i] > 0;
    inter += ia && ib;
    if (ia || ib) {
      ++uni;
      lin_cov += dl / 3;
      srgb_cov += ds / 3;
    }
  }
  std::printf(
      "{\"pixels\": %llu, \"mean_abs_rgb\": %.6f, \"mean_abs_srgb8\": %.4f, "
      "\"mean_abs_rgb_covered\": %.6f, \"mean_abs_srgb8_covered\": %.4f, \"covered_pixels\": %llu, "
      "\"silhouette_iou\": %.6f, \"rmse_rgb\": %.6f, \"rmse_alpha\": %.6f, "
      "\"silhouette_wrong\": %llu}\n",
      (unsigned long long)n, lin / double(n), srgb / double(n), uni ? lin_cov / double(uni) : 0.0,
      uni ? srgb_cov / double(uni) : 0.0, (unsigned long long)uni,
      uni ? double(inter) / double(uni) : 1.0, std::sqrt(sq_rgb / (3.0 * double(n))),
      std::sqrt(sq_alpha / double(n)), (unsigned long long)wrong);
  if (!png.empty()) {
    if (cw == 0 || cx < 0 || cy < 0 || cx + cw > w || cy + ch > h) return Fail("--png needs a --crop inside the image");
    const int gap = 4, ow = (2 * cw) * zoom + gap, oh = ch * zoom;
    std::vector<unsigned char> rgb(size_t(ow) * oh * 3, 255);
    for (int side = 0; side < 2; ++side) {
      const auto& P = side == 0 ? A : B;
      for (int y = 0; y < oh; ++y)
        for (int x = 0; x < cw * zoom; ++x) {
          const size_t src = size_t(cy + y / zoom) * w + cx + x / zoom;
          unsigned char* d = &rgb[(size_t(y) * ow + side * (cw * zoom + gap) + x) * 3];
          d[0] = (unsigned char)ToSrgb8(P.at("R")[src]);
          d[1] = (unsigned char)ToSrgb8(P.at("G")[src]);
          d[2] = (unsigned char)ToSrgb8(P.at("B")[src]);
        }
    }
    if (!WritePng(png, ow, oh, rgb)) return Fail("cannot write " + png);
  }
  return 0;
}

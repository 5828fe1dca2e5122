#include "core/shapes.h"

#include <cmath>
#include <cstdint>
#include <random>
#include <string>

namespace vox {

StatusOr<ShapeVolume> GenerateShape(std::string_view spec) {
  auto colon = spec.find(':');
  std::string name(spec.substr(0, colon));
  if (colon == std::string_view::npos)
    return InvalidArgumentError("shape '" + std::string(spec) + "' needs a size: NAME:SIZE");
  std::string arg(spec.substr(colon + 1));
  char* end = nullptr;
  long long size = std::strtoll(arg.c_str(), &end, 10);
  if (arg.empty() || *end != '\0' || size < 2)
    return InvalidArgumentError("shape '" + std::string(spec) + "': size must be an integer >= 2");
  ShapeVolume vol;
  if (name == "corner") {
    if (size > kMaxLevels)
      return InvalidArgumentError("corner:L takes levels L <= 40");
    vol.levels = int(size);
    uint64_t m = (uint64_t(1) << size) - 1;
    vol.voxels.push_back({m, m, m, kEmptyRef});
    return vol;
  }
  if (size > 4096) return InvalidArgumentError("shape size " + arg + " above 4096");
  int levels = 1;
  while ((1ll << levels) < size) ++levels;
  vol.levels = levels;
  const double n = double(int64_t(1) << levels);
  const double c = n / 2;
  auto add = [&](int64_t x, int64_t y, int64_t z) {
    vol.voxels.push_back({uint64_t(x), uint64_t(y), uint64_t(z), kEmptyRef});
  };
  if (name == "sphere") {
    // Voxels whose centre lies within 2 voxels inside the sphere's surface.
    double r = 0.4 * n;
    for (int64_t z = 0; z < int64_t(n); ++z)
      for (int64_t y = 0; y < int64_t(n); ++y) {
        double dy = y + 0.5 - c, dz = z + 0.5 - c;
        double rr = r * r - dy * dy - dz * dz;
        if (rr < 0) continue;
        double ri = (r - 2) * (r - 2) - dy * dy - dz * dz;
        double xo = std::sqrt(rr), xi = ri > 0 ? std::sqrt(ri) : -1;
        for (int64_t x = int64_t(std::floor(c - xo)); x <= int64_t(std::ceil(c + xo)); ++x) {
          double dx = std::fabs(x + 0.5 - c);
          if (dx * dx + dy * dy + dz * dz > r * r) continue;
          if (xi > 0 && dx < xi) continue;
          add(x, y, z);
        }
      }
  } else if (name == "torus") {
    double R = 0.3 * n, r = 0.1 * n;
    for (int64_t z = 0; z < int64_t(n); ++z)
      for (int64_t y = 0; y < int64_t(n); ++y)
        for (int64_t x = 0; x < int64_t(n); ++x) {
          double dx = x + 0.5 - c, dy = y + 0.5 - c, dz = z + 0.5 - c;
          double q = std::sqrt(dx * dx + dz * dz) - R;
          double f = q * q + dy * dy;
          if (f <= r * r && f > (r - 2) * (r - 2)) add(x, y, z);
        }
  } else if (name == "cubes") {
    std::mt19937_64 rng(12345);
    int count = 24;
    for (int i = 0; i < count; ++i) {
      int64_t s = 1 + int64_t(rng() % uint64_t(std::max(2.0, n / 16)));
      int64_t x0 = int64_t(rng() % uint64_t(n - s)), y0 = int64_t(rng() % uint64_t(n - s)),
              z0 = int64_t(rng() % uint64_t(n - s));
      for (int64_t z = z0; z < z0 + s; ++z)
        for (int64_t y = y0; y < y0 + s; ++y)
          for (int64_t x = x0; x < x0 + s; ++x)
            if (x == x0 || y == y0 || z == z0 || x == x0 + s - 1 || y == y0 + s - 1 ||
                z == z0 + s - 1)
              add(x, y, z);
    }
  } else if (name == "noise") {
    std::mt19937_64 rng(777);
    size_t count = size_t(n * n / 4);
    for (size_t i = 0; i < count; ++i)
      add(int64_t(rng() % uint64_t(n)), int64_t(rng() % uint64_t(n)), int64_t(rng() % uint64_t(n)));
  } else {
    return InvalidArgumentError("unknown shape '" + name +
                                "' (sphere, torus, cubes, noise, corner)");
  }
  return vol;
}

}  // namespace vox

#include "tests/core/test_util.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <set>

#include "core/shapes.h"

namespace vox::testing {

int RayCount(int default_count) {
  const char* env = std::getenv("VOX_CORE_RAYS");
  if (env == nullptr || *env == '\0') return default_count;
  long n = std::strtol(env, nullptr, 10);
  return n > 0 ? int(n) : default_count;
}

double DoubleSetupBound(const Ray& ray, int levels) {
  const double o = std::max({std::fabs(ray.origin.x), std::fabs(ray.origin.y), std::fabs(ray.origin.z)});
  return 8 * 0x1p-53 * (o + std::ldexp(1.0, levels));
}

bool LongRun() {
  const char* env = std::getenv("VOX_CORE_RAYS");
  return env != nullptr && *env != '\0';
}

std::vector<Voxel> ToVoxels(const std::vector<LeafPoint>& points) {
  std::vector<Voxel> out;
  out.reserve(points.size());
  for (const LeafPoint& p : points) out.push_back({int64_t(p.x), int64_t(p.y), int64_t(p.z)});
  return out;
}

std::vector<LeafPoint> ToLeafPoints(const std::vector<Voxel>& voxels) {
  std::vector<LeafPoint> out;
  out.reserve(voxels.size());
  for (const Voxel& v : voxels)
    out.push_back({uint64_t(v[0]), uint64_t(v[1]), uint64_t(v[2]), kEmptyRef});
  return out;
}

double Rng::Uniform(double lo, double hi) {
  double u = double(gen_() >> 11) * 0x1p-53;
  return lo + (hi - lo) * u;
}

int64_t Rng::Int(int64_t lo, int64_t hi) {
  return lo + int64_t(gen_() % uint64_t(hi - lo + 1));
}

glm::dvec3 Rng::Direction(bool allow_zero_components) {
  std::normal_distribution<double> n(0.0, 1.0);
  glm::dvec3 d;
  do {
    d = {n(gen_), n(gen_), n(gen_)};
  } while (d.x == 0 && d.y == 0 && d.z == 0);
  if (allow_zero_components && Chance(0.05)) {
    int a = int(Int(0, 2));
    d[a] = Chance(0.5) ? 0.0 : -0.0;
    if (d.x == 0 && d.y == 0 && d.z == 0) d[(a + 1) % 3] = 1;
  }
  return d * std::ldexp(1.0, int(Int(-30, 30)));
}

glm::dvec3 Rng::PointIn(const Voxel& v) {
  glm::dvec3 p;
  for (int a = 0; a < 3; ++a) {
    double f = Chance(0.02) ? 0.0 : Uniform(0, 1);
    p[a] = double(v[a]) + f;
  }
  return p;
}

std::vector<Voxel> RandomVoxels(Rng& rng, size_t count, const Voxel& lo, int64_t extent) {
  std::set<Voxel> s;
  while (s.size() < count) {
    s.insert({lo[0] + rng.Int(0, extent - 1), lo[1] + rng.Int(0, extent - 1),
              lo[2] + rng.Int(0, extent - 1)});
  }
  return {s.begin(), s.end()};
}

std::vector<Voxel> DenseVoxels(Rng& rng, double density, const Voxel& lo, int64_t extent) {
  std::vector<Voxel> out;
  for (int64_t z = 0; z < extent; ++z)
    for (int64_t y = 0; y < extent; ++y)
      for (int64_t x = 0; x < extent; ++x)
        if (rng.Chance(density)) out.push_back({lo[0] + x, lo[1] + y, lo[2] + z});
  return out;
}

std::vector<Voxel> ShapeVoxels(const std::string& spec, const Voxel& offset, int* levels) {
  auto vol = GenerateShape(spec);
  if (!vol.ok()) return {};
  if (levels) *levels = vol->levels;
  std::vector<Voxel> out = ToVoxels(vol->voxels);
  for (Voxel& v : out)
    for (int a = 0; a < 3; ++a) v[a] += offset[a];
  return out;
}

Ray RayFromOutside(Rng& rng, int levels, const glm::dvec3& target, double distance) {
  const double c = std::ldexp(1.0, levels - 1);
  glm::dvec3 u = rng.Direction(false);
  u /= std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z);
  Ray r;
  r.origin = glm::dvec3(c) + u * distance;
  r.dir = (target - r.origin) * std::ldexp(1.0, int(rng.Int(-20, 20)));
  return r;
}

Ray RayFrom(Rng& rng, const glm::dvec3& origin) {
  Ray r;
  r.origin = origin;
  r.dir = rng.Direction();
  return r;
}

}  // namespace vox::testing

// The tracer's start jump (StartPlane, core/tracer.h) on its own, with the
// tightest plane its promise allows: for each ray, by brute force, s_min is
// where the ray enters the first occupied first-step cell widened by
// kStartPlaneMargin (g its own direction), so the jump lands as close to the
// hit as any beam could put it. The hits (voxel and t, bit for bit, the whole
// Traverse list) must be the plain walk's, on random rays from outside and
// inside the grid, from occupied voxels, along axes, voxel edges and
// corners, and with zero and -0.0 components; and the jump must save walk
// work. Planes a whole first-step cell later must lose hits.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <limits>
#include <set>
#include <tuple>
#include <vector>

#include "core/tracer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

struct Rec {
  glm::i64vec3 v;
  double t;
  bool operator==(const Rec& o) const { return v == o.v && std::memcmp(&t, &o.t, sizeof t) == 0; }
};

template <class T>
std::vector<Rec> Visits(const T& tr, const Ray& r, const StartPlane* sp, TraceCounters* c) {
  std::vector<Rec> out;
  Status s = tr.Traverse(
      r,
      [&](const Hit& h) {
        out.push_back({h.voxel, h.t});
        return out.size() < 30;
      },
      c, sp);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return out;
}

// The tightest valid plane for `r`: g = its unit direction; s_min = the
// entry s of the first widened occupied cell of size `cs` the ray meets
// (t >= 0), +inf when it meets none. `extra` moves it further along (for the
// negative test).
StartPlane TightPlane(const Ray& r, const std::set<std::tuple<int64_t, int64_t, int64_t>>& cells,
                      double cs, double extra = 0.0) {
  StartPlane sp;
  const glm::dvec3 g = glm::normalize(r.dir);
  for (int a = 0; a < 3; ++a) sp.g[a] = g[a];
  const double m = kStartPlaneMargin * 1.001;
  double best_t = std::numeric_limits<double>::infinity();
  for (const auto& [x, y, z] : cells) {
    const double lo[3] = {x * cs - m, y * cs - m, z * cs - m};
    double t0 = 0, t1 = std::numeric_limits<double>::infinity();
    bool hit = true;
    for (int a = 0; a < 3 && hit; ++a) {
      const double hi = lo[a] + cs + 2 * m;
      if (r.dir[a] == 0) {
        hit = r.origin[a] > lo[a] && r.origin[a] < hi;
        continue;
      }
      double ta = (lo[a] - r.origin[a]) / r.dir[a], tb = (hi - r.origin[a]) / r.dir[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      hit = t0 <= t1;
    }
    if (hit) best_t = std::min(best_t, t0);
  }
  const double s0 = glm::dot(g, r.origin), gd = glm::dot(g, r.dir);
  sp.s_min = best_t == std::numeric_limits<double>::infinity()
                 ? std::numeric_limits<double>::infinity()
                 : s0 + best_t * gd * (1 - 1e-12) - 1e-9 + extra;
  return sp;
}

TEST(StartPlane, TightestPlanesKeepEveryHit) {
  Rng rng(2024);
  const int levels = 7;
  const double G = 128;
  std::vector<Voxel> voxels = DenseVoxels(rng, 0.05, {40, 30, 50}, 30);
  for (const Voxel& v : RandomVoxels(rng, 80, {0, 0, 0}, 128)) voxels.push_back(v);
  for (int k = 0; k < 8; ++k) voxels.push_back({16 * k + 15 * (k % 2), 16 * k, 127 - 16 * k});
  uint64_t rays = 0, hits = 0, fewer_cells = 0, lost_with_late_plane = 0;
  for (int bl : {3, 7}) {
    auto built = MemoryOctree::Build(ToLeafPoints(voxels), levels, bl);
    ASSERT_TRUE(built.ok()) << built.status().ToString();
    for (int n1 : {2, 4, 7}) {
      auto tr = Tracer<Fixed64, double>::Create((*built)->view(), n1);
      ASSERT_TRUE(tr.ok());
      auto trl = Tracer<Fixed128, long double>::Create((*built)->view(), n1);
      ASSERT_TRUE(trl.ok());
      const int leaf = std::min(n1, bl);
      const double cs = std::ldexp(1.0, levels - leaf);
      std::set<std::tuple<int64_t, int64_t, int64_t>> cells;
      const int sh = levels - leaf;
      for (const Voxel& v : voxels) cells.insert({v[0] >> sh, v[1] >> sh, v[2] >> sh});
      std::vector<Ray> list;
      for (int k = 0; k < 1200; ++k) {
        const glm::dvec3 target(rng.Uniform(0, G), rng.Uniform(0, G), rng.Uniform(0, G));
        list.push_back(RayFromOutside(rng, levels, target, G * rng.Uniform(0.7, 3.0)));
      }
      for (int k = 0; k < 300; ++k) {
        list.push_back(
            RayFrom(rng, rng.PointIn(voxels[size_t(rng.Int(0, int64_t(voxels.size()) - 1))])));
        list.push_back(
            RayFrom(rng, glm::dvec3(rng.Uniform(0, G), rng.Uniform(0, G), rng.Uniform(0, G))));
      }
      // Along axes, voxel edges and through voxel corners (integer origins).
      for (int k = 0; k < 200; ++k) {
        Ray r;
        const int a = k % 3;
        r.origin =
            glm::dvec3(double(rng.Int(0, 128)), double(rng.Int(0, 128)), double(rng.Int(0, 128)));
        r.origin[a] = k % 2 ? -3.0 : G + 3.0;
        r.dir = glm::dvec3(k % 5 == 0 ? -0.0 : 0.0);
        r.dir[a] = k % 2 ? 1.0 : -1.0;
        if (k % 4 == 1) r.dir[(a + 1) % 3] = k % 8 == 1 ? 1.0 : -1.0;  // face diagonal
        if (k % 8 == 3) r.dir = glm::dvec3(k % 16 == 3 ? 1.0 : -1.0, 1.0, k % 3 ? 1.0 : -1.0);
        list.push_back(r);
      }
      for (const Ray& r : list) {
        const StartPlane sp = TightPlane(r, cells, cs);
        TraceCounters ca, cb;
        const auto plain = Visits(*tr, r, nullptr, &ca);
        const auto jumped = Visits(*tr, r, &sp, &cb);
        ++rays;
        hits += !plain.empty();
        fewer_cells += cb.cells_visited < ca.cells_visited;
        ASSERT_EQ(plain.size(), jumped.size())
            << "bl=" << bl << " n1=" << n1 << " " << RayString(r);
        for (size_t i = 0; i < plain.size(); ++i)
          ASSERT_TRUE(plain[i] == jumped[i])
              << "bl=" << bl << " n1=" << n1 << " hit " << i << " " << RayString(r);
        ASSERT_TRUE(Visits(*trl, r, nullptr, nullptr) == Visits(*trl, r, &sp, nullptr))
            << "fixed128 bl=" << bl << " n1=" << n1 << " " << RayString(r);
        if (!plain.empty()) {
          const StartPlane late = TightPlane(r, cells, cs, 4.0 * cs + 4.0);
          lost_with_late_plane += !(Visits(*tr, r, &late, nullptr) == plain);
        }
      }
    }
  }
  EXPECT_GT(hits, rays / 10);
  EXPECT_GT(fewer_cells, rays / 4);
  EXPECT_GT(lost_with_late_plane, hits / 2);
  printf("%llu rays, %llu hit, %llu visited fewer cells, %llu lost hits with a late plane\n",
         (unsigned long long)rays, (unsigned long long)hits, (unsigned long long)fewer_cells,
         (unsigned long long)lost_with_late_plane);
}

}  // namespace
}  // namespace vox::testing

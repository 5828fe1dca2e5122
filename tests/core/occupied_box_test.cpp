// Misses first (Tracer::SetOccupiedBox): with the occupied box set, the
// tracer must find exactly the first hits (voxel and t, bit for bit) and
// Traverse lists of the plain walk, on random rays and on hard ones: rays
// grazing the box's faces and the widened box's faces, along its edges,
// through its corners, with zero and -0.0 components, and from origins inside
// occupied voxels; and rays that pass outside the box must cost no DDA move.
// A box one voxel too small must change some first hit (the test can fail).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <vector>

#include "core/tracer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

struct BoxScene {
  std::vector<Voxel> voxels;
  int levels = 7;
  Voxel lo{}, hi{};  // inclusive occupied box
  std::shared_ptr<MemoryOctree> tree;
};

// Random voxels in a box well inside a 128^3 grid, plus voxels on all the
// box's corners (so its faces and edges are occupied somewhere).
BoxScene MakeSetup(uint64_t seed, int brick_level) {
  BoxScene s;
  Rng rng(seed);
  const Voxel lo{37, 21, 50}, ext{40, 61, 23};
  s.voxels = DenseVoxels(rng, 0.04, lo, 23);
  for (const Voxel& v : RandomVoxels(rng, 300, lo, 23)) s.voxels.push_back({v[0], v[1] * 2, v[2]});
  for (int c = 0; c < 8; ++c)
    s.voxels.push_back({lo[0] + (c & 1) * (ext[0] - 1), lo[1] + (c >> 1 & 1) * (ext[1] - 1),
                        lo[2] + (c >> 2 & 1) * (ext[2] - 1)});
  s.lo = s.hi = s.voxels[0];
  for (const Voxel& v : s.voxels)
    for (int a = 0; a < 3; ++a) {
      s.lo[a] = std::min(s.lo[a], v[a]);
      s.hi[a] = std::max(s.hi[a], v[a]);
    }
  auto built = MemoryOctree::Build(ToLeafPoints(s.voxels), s.levels, brick_level);
  EXPECT_TRUE(built.ok()) << built.status().ToString();
  s.tree = std::shared_ptr<MemoryOctree>(std::move(built).value());
  return s;
}

std::vector<Ray> HardRays(const BoxScene& s, Rng& rng) {
  std::vector<Ray> rays;
  const double G = double(int64_t(1) << s.levels);
  // Planes: the box's faces, the widened box's faces, and a hair either side.
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    const double m = DefaultTracer::kBoxMargin;
    for (double plane : {double(s.lo[a]), double(s.hi[a] + 1), s.lo[a] - m, s.hi[a] + 1 + m,
                         std::nextafter(s.lo[a] - m, -1e9), std::nextafter(s.hi[a] + 1 + m, 1e9),
                         s.lo[a] - m + 1e-12, double(s.lo[a]) + 0.5})
      for (int k = 0; k < 60; ++k) {
        // A ray lying in the plane x_a = plane, from outside the grid.
        Ray r;
        r.origin[a] = plane;
        r.origin[b] = rng.Uniform(-20, G + 20);
        r.origin[c] = k % 2 ? -10.0 : G + 10.0;
        r.dir[a] = k % 3 == 0 ? -0.0 : 0.0;
        r.dir[b] = rng.Uniform(-1, 1);
        r.dir[c] = k % 2 ? 1.0 : -1.0;
        rays.push_back(r);
        // Along a box edge: two coordinates on face planes.
        Ray e;
        e.origin[a] = plane;
        e.origin[b] = rng.Chance(0.5) ? double(s.lo[b]) : double(s.hi[b] + 1);
        e.origin[c] = -5.0;
        e.dir = glm::dvec3(0.0);
        e.dir[c] = 1.0;
        rays.push_back(e);
      }
  }
  // Through the box's corners (and the widened box's), from random origins.
  for (int corner = 0; corner < 8; ++corner)
    for (double m : {0.0, 1.0, 1.5, 0.999999}) {
      glm::dvec3 p;
      for (int a = 0; a < 3; ++a)
        p[a] = (corner >> a & 1) ? double(s.hi[a] + 1) + m : double(s.lo[a]) - m;
      for (int k = 0; k < 20; ++k) {
        Ray r = RayFromOutside(rng, s.levels, p, G * rng.Uniform(1.0, 3.0));
        rays.push_back(r);
        rays.push_back({p, rng.Direction()});  // starting on the corner
      }
    }
  // Origins inside occupied voxels, and inside the box in empty space.
  for (int k = 0; k < 400; ++k) {
    const Voxel& v = s.voxels[size_t(rng.Int(0, int64_t(s.voxels.size()) - 1))];
    rays.push_back(RayFrom(rng, rng.PointIn(v)));
    glm::dvec3 q;
    for (int a = 0; a < 3; ++a) q[a] = rng.Uniform(double(s.lo[a]), double(s.hi[a] + 1));
    rays.push_back(RayFrom(rng, q));
  }
  return rays;
}

std::vector<Ray> RandomRays(const BoxScene& s, Rng& rng, int n) {
  std::vector<Ray> rays;
  const double G = double(int64_t(1) << s.levels);
  for (int k = 0; k < n; ++k) {
    glm::dvec3 target;  // near the box, often outside it
    for (int a = 0; a < 3; ++a) target[a] = rng.Uniform(s.lo[a] - 30.0, s.hi[a] + 31.0);
    rays.push_back(k % 4 == 3 ? RayFrom(rng, glm::dvec3(rng.Uniform(0, G), rng.Uniform(0, G),
                                                        rng.Uniform(0, G)))
                              : RayFromOutside(rng, s.levels, target, G * rng.Uniform(0.6, 4.0)));
  }
  return rays;
}

bool SameHit(const std::optional<Hit>& a, const std::optional<Hit>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  return a->voxel == b->voxel && std::memcmp(&a->t, &b->t, sizeof(double)) == 0 &&
         a->brick == b->brick && a->payload == b->payload;
}

class OccupiedBoxTest : public ::testing::TestWithParam<std::pair<int, int>> {};

TEST_P(OccupiedBoxTest, SameFirstHitsAndVisitsAsThePlainWalk) {
  const auto [brick_level, n1] = GetParam();
  BoxScene s = MakeSetup(11 + uint64_t(brick_level) * 7 + uint64_t(n1), brick_level);
  auto plain = DefaultTracer::Create(s.tree->view(), n1);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  DefaultTracer boxed = *plain;
  boxed.SetOccupiedBox(s.lo.data(), s.hi.data());
  ASSERT_TRUE(boxed.has_occupied_box());
  Rng rng(5);
  std::vector<Ray> rays = HardRays(s, rng);
  const size_t hard = rays.size();
  for (const Ray& r : RandomRays(s, rng, RayCount(6000))) rays.push_back(r);
  size_t hits = 0, dropped = 0, jumped = 0, failures = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    TraceCounters cp, cb;
    auto a = plain->FirstHit(ray, &cp);
    auto b = boxed.FirstHit(ray, &cb);
    ASSERT_EQ(a.ok(), b.ok());
    if (!a.ok()) continue;
    hits += a->has_value();
    if (cb.total_moves() == 0 && cp.total_moves() > 0) ++dropped;
    if (cb.cells_visited < cp.cells_visited && cb.total_moves() > 0) ++jumped;
    if (!SameHit(*a, *b) && ++failures <= 10)
      ADD_FAILURE() << (i < hard ? "hard" : "random") << " ray " << i << " origin ("
                    << ray.origin.x << ", " << ray.origin.y << ", " << ray.origin.z << ") dir ("
                    << ray.dir.x << ", " << ray.dir.y << ", " << ray.dir.z << "): plain "
                    << (a->has_value() ? "hit" : "miss") << ", boxed "
                    << (b->has_value() ? "hit" : "miss");
    // Traverse: every occupied voxel, in order, the same.
    if (i % 8 == 0) {
      std::vector<glm::i64vec3> va, vb;
      ASSERT_TRUE(plain->Traverse(ray, [&](const Hit& h) { va.push_back(h.voxel); return true; }).ok());
      ASSERT_TRUE(boxed.Traverse(ray, [&](const Hit& h) { vb.push_back(h.voxel); return true; }).ok());
      EXPECT_EQ(va, vb) << "ray " << i;
    }
  }
  printf("bl=%d n1=%d: %zu rays (%zu hard), %zu hit, %zu dropped by the box, %zu walked fewer "
         "cells (the box jump)\n",
         brick_level, n1, rays.size(), hard, hits, dropped, jumped);
  EXPECT_EQ(failures, 0u);
  EXPECT_GT(hits, rays.size() / 10);     // the rays do meet the voxels
  EXPECT_GT(dropped, rays.size() / 10);  // and the box does drop walks
  EXPECT_GT(jumped, rays.size() / 10);   // and shortens others
}

INSTANTIATE_TEST_SUITE_P(Splits, OccupiedBoxTest,
                         ::testing::Values(std::make_pair(7, 7), std::make_pair(4, 4),
                                           std::make_pair(3, 5), std::make_pair(4, 2)));

// The test can fail: a box one voxel short of the occupied one on any face
// changes some first hits.
TEST(OccupiedBox, TooSmallABoxLosesHits) {
  BoxScene s = MakeSetup(3, 4);
  auto plain = DefaultTracer::Create(s.tree->view(), 4);
  ASSERT_TRUE(plain.ok());
  Rng rng(9);
  const std::vector<Ray> rays = HardRays(s, rng);
  for (int a = 0; a < 3; ++a)
    for (int side = 0; side < 2; ++side) {
      Voxel lo = s.lo, hi = s.hi;
      // Shrink by a voxel plus the margin: voxels on that face fall outside.
      const int64_t shrink = 1 + int64_t(DefaultTracer::kBoxMargin);
      (side ? hi[a] : lo[a]) += side ? -shrink : shrink;
      DefaultTracer boxed = *plain;
      boxed.SetOccupiedBox(lo.data(), hi.data());
      int differ = 0;
      for (const Ray& r : rays) {
        auto x = plain->FirstHit(r), y = boxed.FirstHit(r);
        ASSERT_TRUE(x.ok() && y.ok());
        differ += !SameHit(*x, *y);
      }
      EXPECT_GT(differ, 0) << "axis " << a << " side " << side;
    }
}

// A far origin is walked whatever the box (its slabs lose the box in double).
TEST(OccupiedBox, FarOriginsAreWalked) {
  BoxScene s = MakeSetup(4, 4);
  auto plain = DefaultTracer::Create(s.tree->view(), 4);
  ASSERT_TRUE(plain.ok());
  DefaultTracer boxed = *plain;
  boxed.SetOccupiedBox(s.lo.data(), s.hi.data());
  Rng rng(2);
  int hits = 0;
  for (int k = 0; k < 200; ++k) {
    const Voxel& v = s.voxels[size_t(rng.Int(0, int64_t(s.voxels.size()) - 1))];
    const glm::dvec3 target = rng.PointIn(v);
    const glm::dvec3 dir = rng.Direction(false);
    const double far = std::ldexp(1.0, int(rng.Int(20, 60)));
    const Ray r{target - far * glm::normalize(dir), glm::normalize(dir)};
    auto x = plain->FirstHit(r), y = boxed.FirstHit(r);
    ASSERT_TRUE(x.ok() && y.ok());
    EXPECT_TRUE(SameHit(*x, *y)) << k;
    hits += x->has_value();
  }
  EXPECT_GT(hits, 100);
}

}  // namespace
}  // namespace vox::testing

// Checks the exact Reference against a brute force over every occupied voxel
// in plain GMP rationals (no filter, no hierarchy), on rays chosen to be
// degenerate: integer and half-integer origins, integer-ratio directions,
// zero and -0.0 components, tiny components, far origins.
#include <gtest/gtest.h>

#include <optional>

#include "tests/study/reference.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

struct BruteContact {
  bool touch = false, meets = false;
  mpq_class tin;
};

BruteContact Brute(const Ray& ray, const Voxel& v) {
  BruteContact c;
  mpq_class tin(0);
  std::optional<mpq_class> tout;
  bool half_open_ok = true;
  for (int a = 0; a < 3; ++a) {
    mpq_class o(ray.origin[a]), d(ray.dir[a]), lo{double(v[a])}, hi{double(v[a] + 1)};
    if (d == 0) {
      if (o < lo || o > hi) return c;
      if (o == hi) half_open_ok = false;
      continue;
    }
    mpq_class t1 = (lo - o) / d, t2 = (hi - o) / d;
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > tin) tin = t1;
    if (!tout || t2 < *tout) tout = t2;
  }
  c.touch = tin <= *tout;
  c.meets = tin < *tout && half_open_ok;
  c.tin = tin;
  return c;
}

void CompareWithBrute(const Reference& ref, const std::vector<Voxel>& voxels, const Ray& ray) {
  ExactRay er(ray);
  RefHit r = ref.FirstHit(er);
  // Brute force.
  std::optional<mpq_class> best;
  std::vector<BruteContact> cs;
  for (const Voxel& v : voxels) {
    cs.push_back(Brute(ray, v));
    if (cs.back().meets && (!best || cs.back().tin < *best)) best = cs.back().tin;
  }
  ASSERT_EQ(r.hit, best.has_value()) << RayString(ray);
  std::vector<RefContact> all = ref.AllTouched(er);
  size_t touched = 0;
  for (const BruteContact& c : cs) touched += c.touch;
  ASSERT_EQ(all.size(), touched) << RayString(ray);
  for (size_t i = 1; i < all.size(); ++i)
    ASSERT_LE(er.Compare(all[i - 1].contact.tin, all[i].contact.tin), 0) << RayString(ray);
  for (const RefContact& rc : all) {
    BruteContact b = Brute(ray, rc.voxel);
    ASSERT_TRUE(b.touch);
    ASSERT_EQ(b.meets, rc.contact.meets) << RayString(ray) << " " << VoxelString(rc.voxel);
    ASSERT_EQ(b.tin, er.Exact(rc.contact.tin)) << RayString(ray) << " " << VoxelString(rc.voxel);
  }
  if (!best) return;
  ASSERT_EQ(er.Exact(r.tin), *best) << RayString(ray);
  BruteContact mine = Brute(ray, r.voxel);
  ASSERT_TRUE(mine.meets && mine.tin == *best) << RayString(ray);
  bool ambiguous = false;
  for (size_t i = 0; i < voxels.size(); ++i)
    if (voxels[i] != r.voxel && cs[i].touch && cs[i].tin <= *best) ambiguous = true;
  ASSERT_EQ(r.ambiguous, ambiguous) << RayString(ray);
}

// Coordinates on a lattice of quarters, so rays hit edges and corners often.
double Quarter(Rng& rng, int64_t lo, int64_t hi) { return double(rng.Int(lo * 4, hi * 4)) / 4; }

TEST(Reference, MatchesBruteForceOnDegenerateRays) {
  Rng rng(1);
  for (int levels : {3, 4}) {
    const int64_t n = int64_t(1) << levels;
    for (double density : {0.05, 0.3}) {
      std::vector<Voxel> voxels = DenseVoxels(rng, density, {0, 0, 0}, n);
      Reference ref(voxels, levels);
      ASSERT_EQ(ref.size(), voxels.size());
      for (int i = 0; i < 700; ++i) {
        Ray ray;
        for (int a = 0; a < 3; ++a) {
          ray.origin[a] = rng.Chance(0.7) ? Quarter(rng, -2, n + 2) : rng.Uniform(-2, n + 2);
          ray.dir[a] = rng.Chance(0.6) ? double(rng.Int(-3, 3)) : rng.Uniform(-1, 1);
          if (rng.Chance(0.05)) ray.dir[a] = -0.0;
          if (rng.Chance(0.05)) ray.dir[a] = rng.Chance(0.5) ? 1e-300 : -5e-324;
        }
        if (ray.dir.x == 0 && ray.dir.y == 0 && ray.dir.z == 0) ray.dir.x = 1;
        CompareWithBrute(ref, voxels, ray);
        if (::testing::Test::HasFatalFailure()) return;
      }
    }
  }
}

TEST(Reference, MatchesBruteForceOnHugeGrids) {
  Rng rng(2);
  const int levels = 40;
  const int64_t n = int64_t(1) << levels;
  // Clusters near the corners and the middle of a 2^40 grid.
  std::vector<Voxel> voxels;
  for (Voxel lo : {Voxel{0, 0, 0}, Voxel{n - 8, n - 8, n - 8}, Voxel{n / 2 - 4, n / 3, 12345}}) {
    std::vector<Voxel> c = DenseVoxels(rng, 0.2, lo, 8);
    voxels.insert(voxels.end(), c.begin(), c.end());
  }
  Reference ref(voxels, levels);
  for (int i = 0; i < 1500; ++i) {
    const Voxel& target = voxels[size_t(rng.Int(0, int64_t(voxels.size()) - 1))];
    Ray ray;
    if (rng.Chance(0.5)) {
      ray = RayFromOutside(rng, levels, rng.PointIn(target), 1e9 * double(n));
    } else {
      ray.origin = rng.PointIn(target) + glm::dvec3(Quarter(rng, -3, 3), Quarter(rng, -3, 3),
                                                     Quarter(rng, -3, 3));
      for (int a = 0; a < 3; ++a) ray.dir[a] = double(rng.Int(-2, 2));
      if (ray.dir.x == 0 && ray.dir.y == 0 && ray.dir.z == 0) ray.dir.z = -1;
    }
    CompareWithBrute(ref, voxels, ray);
    if (::testing::Test::HasFatalFailure()) return;
  }
}

TEST(Reference, FaceAndEdgeSemantics) {
  // Two voxels side by side across the plane y = 5.
  std::vector<Voxel> voxels = {{3, 4, 0}, {6, 5, 0}};
  Reference ref(voxels, 4);
  // Lying in the face plane y = 5, heading +x: meets row 5 (half-open) and
  // touches row 4, so (3,4,0) is touched first: ambiguous hit on (6,5,0).
  ExactRay in_plane(Ray{{0, 5, 0.5}, {1, 0, 0}});
  RefHit r = ref.FirstHit(in_plane);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.voxel, (Voxel{6, 5, 0}));
  EXPECT_TRUE(r.ambiguous);
  EXPECT_EQ(in_plane.Exact(r.tin), mpq_class(6));
  // The same with -0.0: still the plane y = 5 itself.
  r = ref.FirstHit(ExactRay(Ray{{0, 5, 0.5}, {1, -0.0, 0}}));
  EXPECT_TRUE(r.hit && r.ambiguous && r.voxel == (Voxel{6, 5, 0}));
  // A tiny negative y component leaves the plane downwards: row 4.
  r = ref.FirstHit(ExactRay(Ray{{0, 5, 0.5}, {1, -5e-324, 0}}));
  EXPECT_TRUE(r.hit && !r.ambiguous && r.voxel == (Voxel{3, 4, 0}));
  // A tiny positive one: row 5, strictly above y = 5 for t > 0, so (3,4,0)
  // is not even touched.
  r = ref.FirstHit(ExactRay(Ray{{0, 5, 0.5}, {1, 5e-324, 0}}));
  EXPECT_TRUE(r.hit && !r.ambiguous && r.voxel == (Voxel{6, 5, 0}));
  // Through the corner (4,5,z): touches (3,4,0) at t = 1 exactly.
  r = ref.FirstHit(ExactRay(Ray{{3, 4, 0.5}, {1, 1, 0}}));
  EXPECT_TRUE(r.hit);
  EXPECT_EQ(r.voxel, (Voxel{3, 4, 0}));  // the origin is its corner; it meets it
  EXPECT_FALSE(r.ambiguous);
  // Origin inside an occupied voxel: hit at t = 0.
  ExactRay inside(Ray{{6.5, 5.5, 0.5}, {-1, 0.25, 0}});
  r = ref.FirstHit(inside);
  EXPECT_TRUE(r.hit && r.voxel == (Voxel{6, 5, 0}) && inside.Exact(r.tin) == 0);
  // A miss.
  EXPECT_FALSE(ref.FirstHit(ExactRay(Ray{{0.5, 0.5, 0.5}, {0, 0, 1}})).hit);
}

TEST(Reference, FilterFallsBackToExactArithmetic) {
  std::vector<Voxel> voxels = {{1, 1, 1}};
  Reference ref(voxels, 2);
  // Enters through the edge x = 1, y = 1 exactly, with a direction whose
  // ratio is not a power of two: both entry parameters are 1/3 * k.
  ExactRay er(Ray{{0, 0, 1.5}, {3, 3, 0}});
  RefHit r = ref.FirstHit(er);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(er.Exact(r.tin), mpq_class(1, 3));
  // Two parameters that differ by 1 part in 2^90 are told apart.
  ExactRay close(Ray{{0, 0x1p-70, 0}, {1, 1, 1}});
  ExactRay::T a = close.Plane(0, 1 << 20), b = close.Plane(1, 1 << 20);
  EXPECT_EQ(close.Compare(a, b), 1);
  EXPECT_EQ(close.Compare(b, a), -1);
  EXPECT_GT(close.exact_fallbacks + er.exact_fallbacks, 0u);
}

TEST(Reference, WithinEpsilonSeparatesPrecisionFromLogic) {
  // The ray y = x - 1 + 1e-7 (z = 0.5) clips the corner of (2,2,0) over
  // ~1e-7 and misses the corner (3,2) of (3,1,0) by ~1e-7.
  std::vector<Voxel> voxels = {{2, 2, 0}, {3, 1, 0}, {9, 9, 9}};
  Reference ref(voxels, 4);
  ExactRay er(Ray{{1.5, 0.5 + 1e-7, 0.5}, {1, 1, 0}});
  RefHit r = ref.FirstHit(er);
  ASSERT_TRUE(r.hit);
  ASSERT_FALSE(r.ambiguous);
  ASSERT_EQ(r.voxel, (Voxel{2, 2, 0}));
  Hit near;
  near.voxel = {3, 1, 0};
  near.t = 1.5;
  EXPECT_FALSE(CheckFirstHit(ref, er, r, near).empty());
  EXPECT_TRUE(WithinEpsilon(ref, er, r, near, 1e-6));
  EXPECT_FALSE(WithinEpsilon(ref, er, r, near, 1e-8));
  Hit far;
  far.voxel = {9, 9, 9};
  EXPECT_FALSE(WithinEpsilon(ref, er, r, far, 1e-6));
  // A miss is explained when every voxel met is met over less than eps.
  EXPECT_TRUE(WithinEpsilon(ref, er, r, std::nullopt, 1e-6));
  EXPECT_FALSE(WithinEpsilon(ref, er, r, std::nullopt, 1e-9));
}

}  // namespace
}  // namespace vox::testing

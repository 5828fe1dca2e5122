// Placement (ingest/placement.h): parsing --levels, and the origin and
// levels chosen for occupied bboxes, checked against the placement rules
// computed independently by brute force.
#include <algorithm>
#include <climits>
#include <cstdint>
#include <random>

#include <gtest/gtest.h>

#include "core/octree.h"
#include "ingest/placement.h"

namespace vox {
namespace {

TEST(PlacementTest, ParseLevels) {
  EXPECT_TRUE(ParseLevels("auto")->automatic);
  auto c = ParseLevels("12+5");
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->automatic);
  EXPECT_EQ(c->brick_level, 12);
  EXPECT_EQ(c->brick_depth, 5);
  for (const char* bad : {"", "12", "12+", "+5", "0+5", "5+0", "21+5", "5+21", "a+b", "20+20+1",
                          "-1+5", "12 + 5", "Auto"})
    EXPECT_FALSE(ParseLevels(bad).ok()) << bad;
  EXPECT_TRUE(ParseLevels("20+20").ok());
}

TEST(PlacementTest, AutoPlacement) {
  LevelsChoice a;
  {
    int64_t lo[3] = {-1, -1, -1}, hi[3] = {0, 0, 0};  // straddles an aligned boundary
    auto p = PlaceGrid(lo, hi, a);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->origin[0], -32);
    EXPECT_EQ(p->levels, 6);
    EXPECT_EQ(p->brick_level, 1);
  }
  {
    int64_t lo[3] = {-1000, 0, 5}, hi[3] = {1000, 10, 5};
    auto p = PlaceGrid(lo, hi, a);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->origin[0], -1024);
    EXPECT_EQ(p->origin[2], 0);
    EXPECT_EQ(p->levels, 11);  // 2025 voxels from the origin
    EXPECT_EQ(p->brick_level, 6);
  }
  {
    // OpenVDB's whole index range: 2^32 voxels; bricks deepen so the top keeps 20 levels.
    int64_t lo[3] = {INT32_MIN, 0, 0}, hi[3] = {INT32_MAX, 0, 0};
    auto p = PlaceGrid(lo, hi, a);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->levels, 32);
    EXPECT_EQ(p->brick_level, 20);
  }
}

// True when the cube [origin, origin + 2^levels) holds [lo, hi] on every axis.
bool Covers(const int64_t origin[3], int levels, const int64_t lo[3], const int64_t hi[3]) {
  for (int a = 0; a < 3; ++a)
    if (lo[a] < origin[a] || hi[a] - origin[a] >= (int64_t(1) << levels)) return false;
  return true;
}

TEST(PlacementTest, AutoPlacementFollowsTheRules) {
  std::mt19937_64 rng(7);
  LevelsChoice a;
  for (int trial = 0; trial < 2000; ++trial) {
    int64_t lo[3], hi[3];
    const int64_t span = int64_t(1) << (rng() % 20);
    for (int ax = 0; ax < 3; ++ax) {
      lo[ax] = int64_t(rng() % 2000001) - 1000000;
      hi[ax] = lo[ax] + int64_t(rng() % uint64_t(span));
    }
    auto p = PlaceGrid(lo, hi, a);
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    const int b = p->levels - p->brick_level;
    // 32^3 bricks unless the top would need more than 20 levels.
    EXPECT_EQ(b, std::max(5, p->levels - kMaxStepLevels));
    EXPECT_GE(p->brick_level, 1);
    EXPECT_LE(p->brick_level, kMaxStepLevels);
    for (int ax = 0; ax < 3; ++ax) {
      EXPECT_EQ(p->origin[ax] % (int64_t(1) << b), 0) << "origin not aligned to the brick size";
      // The origin is the bbox min aligned down: no brick-aligned origin is closer.
      EXPECT_LE(p->origin[ax], lo[ax]);
      EXPECT_GT(p->origin[ax] + (int64_t(1) << b), lo[ax]);
    }
    ASSERT_TRUE(Covers(p->origin, p->levels, lo, hi));
    // Smallest such N: one level fewer does not cover (unless at the 1-level minimum).
    if (p->levels > b + 1) EXPECT_FALSE(Covers(p->origin, p->levels - 1, lo, hi));
  }
}

TEST(PlacementTest, ExplicitLevelsAndEmptyBoxes) {
  auto c = ParseLevels("3+2");
  ASSERT_TRUE(c.ok());
  {
    int64_t lo[3] = {5, 6, 7}, hi[3] = {10, 12, 9};
    auto p = PlaceGrid(lo, hi, *c);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->levels, 5);
    EXPECT_EQ(p->brick_level, 3);
    EXPECT_EQ(p->origin[0], 4);
    EXPECT_EQ(p->origin[1], 4);
    EXPECT_EQ(p->origin[2], 4);
  }
  {
    int64_t lo[3] = {0, 0, 0}, hi[3] = {32, 0, 0};  // 33 voxels: more than 2^5
    auto p = PlaceGrid(lo, hi, *c);
    ASSERT_FALSE(p.ok());
    EXPECT_NE(p.status().message().find("2^6"), std::string::npos) << p.status().message();
  }
  {
    int64_t lo[3] = {1, 1, 1}, hi[3] = {0, 0, 0};  // empty
    auto p = PlaceGrid(lo, hi, *c);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->levels, 5);
    EXPECT_EQ(p->origin[0], 0);
    auto q = PlaceGrid(lo, hi, LevelsChoice{});
    ASSERT_TRUE(q.ok());
    EXPECT_EQ(q->brick_level, 1);
    EXPECT_EQ(q->levels, 6);
  }
}

}  // namespace
}  // namespace vox

// Visit::kSkipBrick: a visitor that answers it on a hit makes the walk go on
// after that hit's second-step grid (its first-step voxel), as after a second
// step without a hit. On random rays through dense and sparse voxels, for
// several splits and both of the renderer's tracers, the hits reported are
// exactly the plain walk's hits with those in a skipped first-step voxel
// left out, in the same order, voxel and t bit for bit, and a skipping walk
// makes fewer DDA moves. In a single-step walk it changes nothing.
// SkipBlock(k) likewise leaves out the rest of the hit's aligned block of 2^k
// voxels a side, smaller or larger than a second-step grid, in one step or
// two, and the walk reads fewer cells.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/tracer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

// The visitor answers `answer` on the first hit of every other group of
// hits (voxel >> shift) after the first; shift < 0: the answer skips nothing.
template <class TracerT>
void CheckSkips(const TracerUnderTest<TracerT>& tu, const std::vector<Ray>& rays, Visit answer,
                int shift) {
  const int sh = std::max(shift, 0);
  uint64_t skipped_walks = 0, moves_all = 0, moves_skip = 0, cells_all = 0, cells_skip = 0;
  for (const Ray& ray : rays) {
    std::vector<Hit> all, skipping;
    TraceCounters c_all, c_skip;
    ASSERT_TRUE(tu.tracer.Traverse(ray, [&](const Hit& h) { all.push_back(h); return true; }, &c_all).ok());
    int group = 0;
    glm::i64vec3 last(INT64_MIN);
    ASSERT_TRUE(tu.tracer
                    .Traverse(
                        ray,
                        [&](const Hit& h) {
                          skipping.push_back(h);
                          const glm::i64vec3 g(h.voxel.x >> sh, h.voxel.y >> sh, h.voxel.z >> sh);
                          if (g != last) ++group, last = g;
                          return group % 2 ? answer : Visit::kNext;
                        },
                        &c_skip)
                    .ok());
    // The expected list: the plain walk's hits, keeping only the first hit
    // of each odd-numbered group.
    std::vector<Hit> want;
    int g_count = 0;
    glm::i64vec3 g_last(INT64_MIN);
    for (const Hit& h : all) {
      const glm::i64vec3 g(h.voxel.x >> sh, h.voxel.y >> sh, h.voxel.z >> sh);
      const bool first_in_group = g != g_last;
      if (first_in_group) ++g_count, g_last = g;
      if (shift < 0 || g_count % 2 == 0 || first_in_group) want.push_back(h);
    }
    ASSERT_EQ(skipping.size(), want.size()) << tu.name << " " << RayString(ray);
    for (size_t i = 0; i < want.size(); ++i) {
      EXPECT_EQ(skipping[i].voxel, want[i].voxel) << tu.name << " hit " << i;
      EXPECT_EQ(std::memcmp(&skipping[i].t, &want[i].t, sizeof(double)), 0) << tu.name << " hit " << i;
      EXPECT_EQ(skipping[i].payload, want[i].payload) << tu.name << " hit " << i;
    }
    if (want.size() < all.size()) ++skipped_walks;
    moves_all += c_all.total_moves();
    moves_skip += c_skip.total_moves();
    cells_all += c_all.cells_visited;
    cells_skip += c_skip.cells_visited;
  }
  if (shift > 0) {
    EXPECT_GT(skipped_walks, rays.size() / 10) << tu.name;
    EXPECT_LT(cells_skip, cells_all) << tu.name;
    // Leaving a block costs the same moves as walking through it; leaving
    // a second-step grid costs fewer.
    if (answer == Visit::kSkipBrick) EXPECT_LT(moves_skip, moves_all) << tu.name;
    else EXPECT_LE(moves_skip, moves_all) << tu.name;
  } else {
    EXPECT_EQ(skipped_walks, 0u) << tu.name;
  }
}

std::vector<Ray> RandomRays(Rng& rng, int levels) {
  std::vector<Ray> rays;
  for (int i = 0; i < 300; ++i)
    rays.push_back(RayFromOutside(
        rng, levels,
        glm::dvec3(32, 30, 33) + glm::dvec3(rng.Uniform(-20, 20), rng.Uniform(-20, 20), rng.Uniform(-20, 20)),
        150));
  return rays;
}

TEST(SkipBrickTest, SkipsExactlyTheRestOfTheFirstStepVoxel) {
  const int levels = 6;
  Rng rng(20261205);
  for (double density : {0.9, 0.2}) {
    const std::vector<Voxel> voxels = DenseVoxels(rng, density, Voxel{4, 6, 3}, 54);
    const std::vector<Ray> rays = RandomRays(rng, levels);
    auto check = [&](const auto& tu) {
      const int n2 = tu.tracer.n2();
      CheckSkips(tu, rays, Visit::kSkipBrick, n2 > 0 && n2 < levels ? n2 : -1);
    };
    auto fixed = MakeTracers<DefaultTracer>(voxels, levels, {2, 4}, {2, 3, 4, 6});
    ASSERT_TRUE(fixed.ok()) << fixed.status().ToString();
    for (const auto& tu : *fixed) check(tu);
    auto render = MakeTracers<RenderTracerUnderTest>(voxels, levels, {3}, {3, 5}, true);
    ASSERT_TRUE(render.ok()) << render.status().ToString();
    for (const auto& tu : *render) check(tu);
  }
}

TEST(SkipBrickTest, SkipBlockSkipsExactlyTheRestOfTheBlock) {
  const int levels = 6;
  Rng rng(20261206);
  for (double density : {0.9, 0.2}) {
    const std::vector<Voxel> voxels = DenseVoxels(rng, density, Voxel{4, 6, 3}, 54);
    const std::vector<Ray> rays = RandomRays(rng, levels);
    for (int k : {1, 2, 3, 4}) {
      auto check = [&](const auto& tu) { CheckSkips(tu, rays, SkipBlock(k), k); };
      auto fixed = MakeTracers<DefaultTracer>(voxels, levels, {2, 4}, {2, 3, 4, 6});
      ASSERT_TRUE(fixed.ok()) << fixed.status().ToString();
      for (const auto& tu : *fixed) check(tu);
      auto render = MakeTracers<RenderTracerUnderTest>(voxels, levels, {3}, {3, 5}, true);
      ASSERT_TRUE(render.ok()) << render.status().ToString();
      for (const auto& tu : *render) check(tu);
    }
  }
}

}  // namespace
}  // namespace vox::testing

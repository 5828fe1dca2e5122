// Several rays in flight (Tracer::FirstHits, core/internal/walk_state.h)
// against the one-ray walk (Tracer::FirstHit): for K = 1, 4, 8, 16 rays in
// flight, handing over at top-pool cells or not, every ray's first hit (voxel, t bit for bit,
// brick, payload) and the summed counters (moves per axis, skips, cells, transitions, fetches,
// hits) must be FirstHit's, over the generated shapes with and without
// bricks, single step and two steps, on random rays from outside and inside,
// along axes, voxel edges and through voxel corners, with -0.0 components.
#include <gtest/gtest.h>

#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "core/shapes.h"
#include "core/tracer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

std::vector<Ray> TestRays(Rng& rng, int levels, const std::vector<LeafPoint>& voxels) {
  const double g = std::ldexp(1.0, levels);
  std::vector<Ray> rays;
  for (int k = 0; k < 1500; ++k) {
    const glm::dvec3 target(rng.Uniform(0, g), rng.Uniform(0, g), rng.Uniform(0, g));
    rays.push_back(RayFromOutside(rng, levels, target, g * rng.Uniform(0.7, 3.0)));
  }
  for (int k = 0; k < 300; ++k) {
    const LeafPoint& v = voxels[size_t(rng.Int(0, int64_t(voxels.size()) - 1))];
    rays.push_back(RayFrom(rng, rng.PointIn({int64_t(v.x), int64_t(v.y), int64_t(v.z)})));
    rays.push_back(
        RayFrom(rng, glm::dvec3(rng.Uniform(0, g), rng.Uniform(0, g), rng.Uniform(0, g))));
  }
  // Along axes, voxel edges and face diagonals, and through voxel corners.
  const int64_t gi = int64_t(1) << levels;
  for (int k = 0; k < 400; ++k) {
    Ray r;
    const int a = k % 3;
    r.origin = glm::dvec3(double(rng.Int(0, gi)), double(rng.Int(0, gi)), double(rng.Int(0, gi)));
    if (k % 7 == 2) r.origin[(a + 2) % 3] += 0.5;  // along a face, not an edge
    r.origin[a] = k % 2 ? -3.0 : g + 3.0;
    r.dir = glm::dvec3(k % 5 == 0 ? -0.0 : 0.0);
    r.dir[a] = k % 2 ? 1.0 : -1.0;
    if (k % 4 == 1) r.dir[(a + 1) % 3] = k % 8 == 1 ? 1.0 : -1.0;
    if (k % 8 == 3) r.dir = glm::dvec3(k % 16 == 3 ? 1.0 : -1.0, 1.0, k % 3 ? 1.0 : -1.0);
    rays.push_back(r);
  }
  return rays;
}

bool SameHit(const std::optional<Hit>& a, const std::optional<Hit>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  return a->voxel == b->voxel && std::memcmp(&a->t, &b->t, sizeof a->t) == 0 &&
         a->brick == b->brick && a->payload == b->payload;
}

bool SameCounters(const TraceCounters& a, const TraceCounters& b) {
  return a.rays == b.rays && a.moves[0] == b.moves[0] && a.moves[1] == b.moves[1] &&
         a.moves[2] == b.moves[2] && a.driving_moves == b.driving_moves &&
         a.passive_moves == b.passive_moves && a.skips == b.skips &&
         a.cells_visited == b.cells_visited && a.transitions == b.transitions &&
         a.brick_fetches == b.brick_fetches && a.hits == b.hits;
}

template <class TracerT>
void CheckShape(const std::string& spec, const std::vector<int>& brick_levels,
                const std::vector<int>& n1s, uint64_t seed) {
  auto vol = GenerateShape(spec);
  ASSERT_TRUE(vol.ok()) << vol.status().ToString();
  Rng rng(seed);
  const std::vector<Ray> rays = TestRays(rng, vol->levels, vol->voxels);
  for (int bl : brick_levels) {
    auto tree = MemoryOctree::Build(vol->voxels, vol->levels, bl);
    ASSERT_TRUE(tree.ok()) << tree.status().ToString();
    for (int n1 : n1s) {
      auto tracer = TracerT::Create((*tree)->view(), n1);
      ASSERT_TRUE(tracer.ok()) << tracer.status().ToString();
      const std::string where = spec + " bl=" + std::to_string(bl) + " n1=" + std::to_string(n1);
      TraceCounters one;
      std::vector<std::optional<Hit>> expected;
      for (const Ray& r : rays) {
        auto h = tracer->FirstHit(r, &one);
        ASSERT_TRUE(h.ok()) << where << " " << h.status().ToString();
        expected.push_back(*h);
      }
      ASSERT_GT(one.hits, rays.size() / 20) << where;
      for (int k : {1, 4, 8, 16})
        for (bool yield_in_top : {true, false}) {
          const std::string run =
              where + " k=" + std::to_string(k) + (yield_in_top ? "" : " top at once");
          TraceCounters many;
          std::vector<std::optional<Hit>> got(rays.size());
          Status s =
              tracer->FirstHits(rays.data(), rays.size(), got.data(), k, &many, yield_in_top);
          ASSERT_TRUE(s.ok()) << run << " " << s.ToString();
          for (size_t i = 0; i < rays.size(); ++i)
            ASSERT_TRUE(SameHit(expected[i], got[i]))
                << run << " ray " << i << " " << RayString(rays[i]);
          EXPECT_TRUE(SameCounters(one, many))
              << run << "\none-ray:  " << one.ToString() << "\nin flight: " << many.ToString();
        }
    }
  }
}

TEST(InterleavedWalk, SphereMatchesTheOneRayWalk) {
  CheckShape<DefaultTracer>("sphere:128", {3, 5, 7}, {2, 4, 7}, 1);
}
TEST(InterleavedWalk, NoiseMatchesTheOneRayWalk) {
  CheckShape<DefaultTracer>("noise:128", {4, 7}, {3, 6, 7}, 2);
}
TEST(InterleavedWalk, TorusAndCubesMatchTheOneRayWalk) {
  CheckShape<DefaultTracer>("torus:64", {2, 6}, {1, 3, 6}, 3);
  CheckShape<DefaultTracer>("cubes:128", {4}, {4, 7}, 4);
}
TEST(InterleavedWalk, RenderTracerMatchesTheOneRayWalk) {
  CheckShape<Tracer<Fixed64, double>>("sphere:256", {3}, {4, 6}, 5);
  CheckShape<Tracer<Fixed128, double>>("cubes:64", {3}, {3}, 6);
}

// An invalid ray ends the batch with FirstHit's error.
TEST(InterleavedWalk, InvalidRayIsAnError) {
  auto vol = GenerateShape("sphere:32");
  ASSERT_TRUE(vol.ok());
  auto tree = MemoryOctree::Build(vol->voxels, vol->levels, 3);
  ASSERT_TRUE(tree.ok());
  auto tracer = DefaultTracer::Create((*tree)->view(), 2);
  ASSERT_TRUE(tracer.ok());
  std::vector<Ray> rays(40, Ray{{-5, 16.5, 16.5}, {1, 0.01, 0.02}});
  rays[30].dir = {0, 0, 0};
  std::vector<std::optional<Hit>> hits(rays.size());
  Status s = tracer->FirstHits(rays.data(), rays.size(), hits.data(), 8);
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.ToString(), tracer->FirstHit(rays[30]).status().ToString());
}

}  // namespace
}  // namespace vox::testing

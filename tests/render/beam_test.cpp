// Beam start distances (render/beam.h, StartPlane in core/tracer.h): every
// ray of a block, traced with its block's plane, must meet exactly the
// voxels of the plain walk (voxel and t bit for bit, the whole Traverse list),
// on random perspective and orthographic cameras over random and shaped
// scenes, on rays through voxel edges and corners, axis-parallel rays, rays
// at block corners (silhouettes of the beam), and from origins inside
// occupied voxels. Independently of the tracer, the plane itself must keep
// its promise: every ray point before it lies more than kStartPlaneMargin
// from each occupied first-step cell (checked by brute force), so a start
// past the first hit cannot happen. A plane moved past the first hit must
// change some hits (the comparison can fail).
#include "render/beam.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <set>
#include <string>
#include <tuple>
#include <type_traits>
#include <vector>

#include "core/tracer.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "tests/core/test_util.h"

namespace vox::testing {
namespace {

// tests/core hold RenderTracerUnderTest to the exact reference as the
// render's tracer: it must stay the type vox-render traces with.
static_assert(std::is_same_v<RenderTracer, RenderTracerUnderTest>);
static_assert(std::is_same_v<LodLevelTracer, RenderTracerUnderTest>);

struct HitRec {
  glm::i64vec3 voxel;
  double t;
  bool operator==(const HitRec& o) const {
    return voxel == o.voxel && std::memcmp(&t, &o.t, sizeof t) == 0;
  }
};

template <class TracerT>
std::vector<HitRec> Hits(const TracerT& tr, const Ray& r, const StartPlane* sp,
                         TraceCounters* c = nullptr) {
  std::vector<HitRec> out;
  Status s = tr.Traverse(
      r,
      [&](const Hit& h) {
        out.push_back({h.voxel, h.t});
        return out.size() < 40;
      },
      c, sp);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return out;
}

// A camera in grid space with vox::Camera's pixel model: pixel (x, y) maps
// affinely to an unnormalised direction (perspective) or an origin
// (orthographic).
struct GridCam {
  bool persp = true;
  glm::dvec3 pos, fwd, right, up;  // right and up already scaled to the half image
  int w = 32, h = 32;
  Ray PixelRay(double x, double y) const {
    const double sx = 2.0 * x / w - 1.0, sy = 1.0 - 2.0 * y / h;
    Ray r;
    if (persp) {
      r.origin = pos;
      r.dir = glm::normalize(fwd + sx * right + sy * up);
    } else {
      r.origin = pos + sx * right + sy * up;
      r.dir = fwd;
    }
    return r;
  }
  BeamCorners Corners(double x0, double y0, double x1, double y1) const {
    BeamCorners b;
    const double xs[4] = {x0, x1, x1, x0}, ys[4] = {y0, y0, y1, y1};
    for (int i = 0; i < 4; ++i) {
      const Ray r = PixelRay(xs[i], ys[i]);
      b.o[i] = r.origin;
      b.d[i] = r.dir;
    }
    return b;
  }
};

GridCam LookAt(bool persp, const glm::dvec3& pos, const glm::dvec3& target, double half, int w = 32,
               int h = 32) {
  GridCam c;
  c.persp = persp;
  c.pos = pos;
  c.w = w;
  c.h = h;
  c.fwd = glm::normalize(target - pos);
  glm::dvec3 up0 = std::fabs(c.fwd.y) < 0.9 ? glm::dvec3(0, 1, 0) : glm::dvec3(1, 0, 0);
  glm::dvec3 r = glm::normalize(glm::cross(c.fwd, up0));
  glm::dvec3 u = glm::cross(r, c.fwd);
  c.right = half * r;
  c.up = half * u;
  return c;
}

struct Scene {
  std::string name;
  int levels = 7;
  std::vector<Voxel> voxels;
};

// Occupied cells of `level` (coordinates >> (levels - level)).
std::set<std::tuple<int64_t, int64_t, int64_t>> OccupiedCells(const Scene& s, int level) {
  std::set<std::tuple<int64_t, int64_t, int64_t>> out;
  const int sh = s.levels - level;
  for (const Voxel& v : s.voxels) out.insert({v[0] >> sh, v[1] >> sh, v[2] >> sh});
  return out;
}

struct Totals {
  uint64_t rays = 0, hits = 0, jumped = 0, block_misses = 0, contract_points = 0;
  uint64_t skips_plain = 0, skips_beam = 0;
};

// Traces every block of `cam` with and without its plane and compares.
// `samples`: sub-pixel positions per pixel (centre, corners, edge midpoints).
template <class TracerT>
void CheckCamera(const Scene& scene, MemoryOctree& tree, const TracerT& tr, int n1,
                 const GridCam& cam, int block, const std::string& what, Totals* tot,
                 bool check_contract, int num_subs) {
  const OctreeView view = tree.view();
  const int leaf = std::min(n1, view.brick_level);
  const auto cells =
      check_contract ? OccupiedCells(scene, leaf) : decltype(OccupiedCells(scene, 1)){};
  const double cs = std::ldexp(1.0, scene.levels - leaf);
  const double G = std::ldexp(1.0, scene.levels);
  const double subs[][2] = {{0.5, 0.5}, {0, 0}, {1, 0}, {0, 1}, {1, 1}, {0.5, 0}, {0, 0.5}};
  for (int by = 0; by < cam.h; by += block)
    for (int bx = 0; bx < cam.w; bx += block) {
      const int x1 = std::min(bx + block, cam.w), y1 = std::min(by + block, cam.h);
      const StartPlane sp = BeamStartPlane(view, n1, cam.Corners(bx, by, x1, y1));
      if (sp.s_min == INFINITY) ++tot->block_misses;
      for (int py = by; py < y1; ++py)
        for (int px = bx; px < x1; ++px)
          for (int si = 0; si < num_subs; ++si) {
            const auto& sub = subs[si];
            const Ray r = cam.PixelRay(px + sub[0], py + sub[1]);
            TraceCounters ca, cb;
            const std::vector<HitRec> plain = Hits(tr, r, nullptr, &ca);
            const std::vector<HitRec> beam = Hits(tr, r, &sp, &cb);
            ++tot->rays;
            tot->skips_plain += ca.skips;
            tot->skips_beam += cb.skips;
            if (!plain.empty()) ++tot->hits;
            if (cb.cells_visited < ca.cells_visited) ++tot->jumped;
            ASSERT_EQ(plain.size(), beam.size())
                << what << " pixel (" << px + sub[0] << ", " << py + sub[1] << ") " << RayString(r)
                << " s_min " << sp.s_min;
            for (size_t i = 0; i < plain.size(); ++i)
              ASSERT_TRUE(plain[i] == beam[i])
                  << what << " hit " << i << " pixel (" << px + sub[0] << ", " << py + sub[1]
                  << ") " << RayString(r) << ": plain voxel " << plain[i].voxel[0] << ","
                  << plain[i].voxel[1] << "," << plain[i].voxel[2] << " t " << plain[i].t
                  << ", beam voxel " << beam[i].voxel[0] << "," << beam[i].voxel[1] << ","
                  << beam[i].voxel[2] << " t " << beam[i].t;
            const double gd = sp.g[0] * r.dir.x + sp.g[1] * r.dir.y + sp.g[2] * r.dir.z;
            const double s0 = sp.g[0] * r.origin.x + sp.g[1] * r.origin.y + sp.g[2] * r.origin.z;
            // The plane never lies past the first hit (where the ray enters it).
            if (!plain.empty() && sp.s_min > -INFINITY) {
              const double s_hit = s0 + plain[0].t * gd;
              ASSERT_LT(sp.s_min, s_hit) << what << " " << RayString(r);
            }
            // The promise, by brute force: ray points before the plane are more
            // than the margin away from every occupied cell of the leaf level.
            if (check_contract && &sub == &subs[0] && (px + py) % 3 == 0 && sp.s_min > -INFINITY &&
                gd > 0) {
              const double t_end = std::min(sp.s_min == INFINITY ? 1e300 : (sp.s_min - s0) / gd,
                                            4.0 * G / glm::length(r.dir));
              const double step = 0.25 / glm::length(r.dir);
              for (double t = 0; t < t_end; t += step) {
                const glm::dvec3 p = r.origin + t * r.dir;
                int64_t lo[3], hi[3];
                bool inside = true;
                for (int a = 0; a < 3; ++a) {
                  lo[a] = int64_t(std::floor((p[a] - kStartPlaneMargin) / cs));
                  hi[a] = int64_t(std::floor((p[a] + kStartPlaneMargin) / cs));
                  if (hi[a] < 0 || lo[a] * cs >= G) inside = false;
                }
                if (!inside) continue;
                ++tot->contract_points;
                for (int64_t x = lo[0]; x <= hi[0]; ++x)
                  for (int64_t y = lo[1]; y <= hi[1]; ++y)
                    for (int64_t z = lo[2]; z <= hi[2]; ++z)
                      ASSERT_EQ(cells.count({x, y, z}), 0u)
                          << what << ": point t=" << t << " before the plane is within "
                          << kStartPlaneMargin << " of occupied cell " << x << "," << y << "," << z
                          << " " << RayString(r);
              }
            }
          }
    }
}

std::vector<Scene> Scenes() {
  std::vector<Scene> out;
  Rng rng(12);
  {
    Scene s{"clusters", 7, {}};
    s.voxels = DenseVoxels(rng, 0.06, {50, 40, 60}, 24);
    for (const Voxel& v : RandomVoxels(rng, 60, {0, 0, 0}, 128)) s.voxels.push_back(v);
    out.push_back(s);
  }
  {
    Scene s{"lattice", 7, {}};  // voxels on a 16-voxel lattice: cells meet at edges and corners
    for (int x = 0; x < 128; x += 16)
      for (int y = 0; y < 128; y += 16)
        for (int z = 0; z < 128; z += 16)
          if ((x + 2 * y + 3 * z) % 48 != 0) s.voxels.push_back({x + 15 * (x % 32 == 0), y, z});
    out.push_back(s);
  }
  {
    Scene s{"sphere", 7, {}};
    int levels = 0;
    s.voxels = ShapeVoxels("sphere:64", {32, 32, 32}, &levels);
    s.levels = 7;
    out.push_back(s);
  }
  return out;
}

std::vector<std::pair<GridCam, std::string>> Cameras(Rng& rng, const Scene& s) {
  std::vector<std::pair<GridCam, std::string>> cams;
  const double G = std::ldexp(1.0, s.levels);
  const glm::dvec3 c(G / 2);
  for (int k = 0; k < 4; ++k) {  // random perspective, from outside
    glm::dvec3 dir = glm::normalize(rng.Direction(false));
    glm::dvec3 pos = c + dir * rng.Uniform(0.9 * G, 2.5 * G);
    glm::dvec3 tgt(rng.Uniform(0, G), rng.Uniform(0, G), rng.Uniform(0, G));
    cams.push_back({LookAt(true, pos, tgt, std::tan(rng.Uniform(0.15, 0.7))), "persp"});
  }
  for (int k = 0; k < 2; ++k) {  // random orthographic
    glm::dvec3 dir = glm::normalize(rng.Direction(false));
    cams.push_back({LookAt(false, c + 1.5 * G * dir, c, rng.Uniform(0.3, 0.8) * G), "ortho"});
  }
  // From inside: an occupied voxel's centre and a random point.
  const Voxel& v = s.voxels[s.voxels.size() / 2];
  const glm::dvec3 vc(v[0] + 0.5, v[1] + 0.5, v[2] + 0.5);
  cams.push_back({LookAt(true, vc, vc + glm::normalize(rng.Direction(false)), 1.2), "in-voxel"});
  cams.push_back({LookAt(true, glm::dvec3(rng.Uniform(0, G), rng.Uniform(0, G), rng.Uniform(0, G)),
                         c + glm::dvec3(0.3, -0.2, 0.1), 0.9),
                  "inside"});
  // Axis-parallel orthographic: pixel corners on integer coordinates, so
  // rays run along voxel edges and through corners; also from the far side.
  for (int a = 0; a < 3; ++a)
    for (int sgn : {1, -1}) {
      GridCam o;
      o.persp = false;
      o.fwd = glm::dvec3(0.0);
      o.fwd[a] = sgn;
      o.right = glm::dvec3(0.0);
      o.up = glm::dvec3(0.0);
      o.right[(a + 1) % 3] = 64;  // 32 pixels over 128 voxels: 4 voxels a pixel
      o.up[(a + 2) % 3] = 64;
      o.pos = c;
      o.pos[a] = sgn > 0 ? -7.0 : G + 7.0;
      cams.push_back({o, "axis-ortho"});
    }
  // Diagonal orthographic through lattice corners: directions (1,1,0), (1,1,1).
  for (glm::dvec3 d : {glm::dvec3(1, 1, 0), glm::dvec3(1, 1, 1), glm::dvec3(-1, 1, -1)}) {
    GridCam o = LookAt(false, c - 2.0 * G * glm::normalize(d), c, 0.75 * G);
    o.pos = glm::round(o.pos);
    cams.push_back({o, "diag-ortho"});
  }
  // Perspective whose centre ray is axis-parallel (an even image: the centre
  // is a block corner), and one looking straight down a lattice line.
  cams.push_back(
      {LookAt(true, glm::dvec3(64, 64, -40), glm::dvec3(64, 64, 64), 0.5), "axis-persp"});
  cams.push_back(
      {LookAt(true, glm::dvec3(16, 32, 200), glm::dvec3(16, 32, 0), 0.3), "lattice-persp"});
  return cams;
}

template <class TracerT>
void RunAll(const char* tracer_name, int num_subs) {
  Totals tot;
  Rng rng(77);
  for (const Scene& s : Scenes()) {
    for (int bl : {2, 4, 7}) {
      auto built = MemoryOctree::Build(ToLeafPoints(s.voxels), s.levels, bl);
      ASSERT_TRUE(built.ok()) << built.status().ToString();
      std::shared_ptr<MemoryOctree> tree = std::move(built).value();
      for (int n1 : {2, 3, 5, 7}) {
        auto tr = TracerT::Create(tree->view(), n1);
        ASSERT_TRUE(tr.ok()) << tr.status().ToString();
        int k = 0;
        for (const auto& [cam, cname] : Cameras(rng, s)) {
          const int block = (k++ % 3 == 0) ? 5 : 8;  // 5: partial blocks at the image edge
          const std::string what = std::string(tracer_name) + " " + s.name +
                                   " bl=" + std::to_string(bl) + " n1=" + std::to_string(n1) + " " +
                                   cname + " block " + std::to_string(block);
          CheckCamera(s, *tree, *tr, n1, cam, block, what, &tot, /*check_contract=*/bl == 4,
                      num_subs);
          if (::testing::Test::HasFatalFailure()) return;
        }
      }
    }
  }
  // The beam did something: rays jumped, blocks were misses, fewer skips.
  EXPECT_GT(tot.hits, tot.rays / 20);
  EXPECT_GT(tot.jumped, tot.rays / 10);
  EXPECT_GT(tot.block_misses, 0u);
  EXPECT_LT(tot.skips_beam, tot.skips_plain);
  EXPECT_GT(tot.contract_points, 100000u);
  printf(
      "%s: %llu rays, %llu hit, %llu with fewer cells visited, %llu block misses, skips %llu -> "
      "%llu\n",
      tracer_name, (unsigned long long)tot.rays, (unsigned long long)tot.hits,
      (unsigned long long)tot.jumped, (unsigned long long)tot.block_misses,
      (unsigned long long)tot.skips_plain, (unsigned long long)tot.skips_beam);
}

TEST(BeamStart, SameHitsAsPlainWalk64) { RunAll<Tracer<Fixed64, double>>("fixed64/double", 7); }
TEST(BeamStart, SameHitsAsPlainWalk128) { RunAll<Tracer<Fixed128, double>>("fixed128/double", 2); }
TEST(BeamStart, SameHitsAsPlainWalkLongDouble) {
  RunAll<Tracer<Fixed64, long double>>("fixed64/long double", 2);
}

// A plane past the first hit (as a broken beam would give) changes hits:
// the comparison above can fail.
TEST(BeamStart, PlanePastTheHitIsCaught) {
  const Scene s = Scenes()[0];
  auto built = MemoryOctree::Build(ToLeafPoints(s.voxels), s.levels, 4);
  ASSERT_TRUE(built.ok());
  auto tr = Tracer<Fixed64, double>::Create((*built)->view(), 3);
  ASSERT_TRUE(tr.ok());
  Rng rng(5);
  int changed = 0, hits = 0;
  const GridCam cam = LookAt(true, glm::dvec3(-60, 70, 30), glm::dvec3(62, 52, 72), 0.4);
  for (int py = 0; py < cam.h; ++py)
    for (int px = 0; px < cam.w; ++px) {
      const Ray r = cam.PixelRay(px + 0.5, py + 0.5);
      const auto plain = Hits(*tr, r, nullptr);
      if (plain.empty()) continue;
      ++hits;
      StartPlane bad;
      const glm::dvec3 g = glm::normalize(r.dir);
      for (int a = 0; a < 3; ++a) bad.g[a] = g[a];
      // 40 voxels past the hit: more than one first-step cell (16 voxels).
      bad.s_min = glm::dot(g, r.origin) + plain[0].t * glm::dot(g, r.dir) + 40.0;
      if (!(Hits(*tr, r, &bad) == plain)) ++changed;
    }
  EXPECT_GT(hits, 50);
  EXPECT_GT(changed, hits / 2);
}

// A beam wholly outside the grid, or pointing away from everything, is a
// block miss; corners over 90 degrees apart give no hint at all.
TEST(BeamStart, MissesAndUnusableBeams) {
  const Scene s = Scenes()[0];
  auto built = MemoryOctree::Build(ToLeafPoints(s.voxels), s.levels, 4);
  ASSERT_TRUE(built.ok());
  const OctreeView view = (*built)->view();
  const GridCam away = LookAt(true, glm::dvec3(-50, 64, 64), glm::dvec3(-200, 64, 64), 0.3);
  EXPECT_EQ(BeamStartPlane(view, 3, away.Corners(0, 0, 8, 8)).s_min, INFINITY);
  BeamCorners wide = away.Corners(0, 0, 8, 8);  // 180 degrees across: no usable beam
  wide.d[0] = glm::dvec3(1, 0, 0);
  wide.d[1] = glm::dvec3(0, 0, 1);
  wide.d[2] = glm::dvec3(-1, 0, -0.5);
  wide.d[3] = glm::dvec3(0, 0, 1);
  EXPECT_EQ(BeamStartPlane(view, 3, wide).s_min, -INFINITY);
  const GridCam far = LookAt(true, glm::dvec3(-1e12, 64, 64), glm::dvec3(64, 64, 64), 1e-12);
  EXPECT_EQ(BeamStartPlane(view, 3, far.Corners(0, 0, 8, 8)).s_min, -INFINITY);
  BeamCorners nan = away.Corners(0, 0, 8, 8);
  nan.d[2].x = NAN;
  EXPECT_EQ(BeamStartPlane(view, 3, nan).s_min, -INFINITY);
}

}  // namespace
}  // namespace vox::testing

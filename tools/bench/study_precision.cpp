// vox-study's precision part: every traversal variant (tests/study/variants.h)
// traces the same rays over the same octrees; each first hit is checked against
// the exact GMP reference (tests/study/reference.h) with its acceptance rule
// (an ambiguous reference answer accepts any voxel the ray touches no later),
// on random rays and on the hard-case families, and on the primary rays of a
// rendered image. tools/bench/study.py makes the tables.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>

#include "core/shapes.h"
#include "render/grid_transform.h"
#include "tests/core/test_util.h"
#include "tests/study/reference.h"
#include "tests/study/variants.h"
#include "tools/bench/study.h"

namespace vox::bench {
namespace {

using testing::CheckFirstHit;
using testing::ExactRay;
using testing::Reference;
using testing::RefHit;
using testing::Rng;
using testing::Voxel;

// Every occupied voxel of an octree (top and bricks), in grid coordinates.
Status CollectVoxels(const OctreeView& view, const CompactCell* pool, CompactCell cell, int bits,
                     uint64_t x, uint64_t y, uint64_t z, std::vector<Voxel>* out) {
  const uint64_t half = uint64_t(1) << (bits - 1);
  for (unsigned digit = 0; digit < 8; ++digit) {
    ChildRef child = ChildOf(cell, digit, view.levels - bits, view);
    if (child.kind == ChildRef::kEmpty) continue;
    uint64_t cx = x + (digit & 1 ? half : 0), cy = y + (digit & 2 ? half : 0), cz = z + (digit & 4 ? half : 0);
    if (child.kind == ChildRef::kPayload) {
      out->push_back({int64_t(cx), int64_t(cy), int64_t(cz)});
      continue;
    }
    if (child.kind == ChildRef::kBrick) {
      if (view.bricks == nullptr) return CorruptionError("brick reference without a brick source");
      VOX_ASSIGN_OR_RETURN(BrickView b, view.bricks->FetchBrick(child.index));
      VOX_RETURN_IF_ERROR(CollectVoxels(view, b.cells, b.cells[0], bits - 1, cx, cy, cz, out));
    } else {
      VOX_RETURN_IF_ERROR(CollectVoxels(view, pool, pool[child.index], bits - 1, cx, cy, cz, out));
    }
  }
  return OkStatus();
}

struct RayFamily {
  std::string name;
  std::vector<Ray> rays;
  std::vector<ExactRay> exact;
  std::vector<RefHit> expected;
};

struct Scenario {
  std::string name, description;
  int levels = 0, n1 = 0;
  std::vector<Voxel> voxels;
  std::unique_ptr<MemoryOctree> tree;
  std::unique_ptr<Reference> ref;
  std::vector<RayFamily> families;  // families[0]: random rays (timed)
};

glm::dvec3 Center(const Voxel& v) { return {v[0] + 0.5, v[1] + 0.5, v[2] + 0.5}; }

// The ray families of the tracer's hard-case tests (tests/core/tracer_hard_cases_test.cpp), aimed at the scenario's voxels.
void MakeFamilies(Scenario* s, int per_family, uint64_t seed) {
  Rng rng(seed);
  auto pick = [&]() -> const Voxel& { return s->voxels[size_t(rng.Int(0, int64_t(s->voxels.size()) - 1))]; };
  Voxel lo = s->voxels[0], hi = s->voxels[0];
  for (const Voxel& v : s->voxels)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], v[a]);
      hi[a] = std::max(hi[a], v[a]);
    }
  const double extent = double(hi[0] - lo[0] + 1);
  auto unit = [&]() {
    glm::dvec3 u = rng.Direction(false);
    return u / std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z);
  };
  auto scale = [&](glm::dvec3 d) { return d * std::ldexp(1.0, int(rng.Int(-20, 20))); };
  std::vector<RayFamily> f(6);
  f[0].name = "random";
  f[1].name = "axis-parallel";
  f[2].name = "lattice edges/corners";
  f[3].name = "grazing";
  f[4].name = "tiny components";
  f[5].name = "far origins";
  for (int i = 0; i < per_family; ++i) {
    {  // random: from 1..4 extents away towards a point near the object
      glm::dvec3 target = Center(pick()) + glm::dvec3(rng.Uniform(-2, 2), rng.Uniform(-2, 2), rng.Uniform(-2, 2));
      Ray r;
      r.origin = target + unit() * (extent * rng.Uniform(1, 4));
      r.dir = scale(target - r.origin);
      f[0].rays.push_back(r);
    }
    {  // axis-parallel on integer / half-integer lattice lines
      const Voxel& v = pick();
      int a = int(rng.Int(0, 2)), b = (a + 1) % 3, c = (a + 2) % 3;
      int sign = rng.Chance(0.5) ? 1 : -1;
      Ray r;
      r.origin[b] = double(v[b]) + 0.5 * double(rng.Int(0, 2));
      r.origin[c] = double(v[c]) + 0.5 * double(rng.Int(0, 2));
      r.origin[a] = sign > 0 ? double(lo[a]) - double(rng.Int(1, 50)) : double(hi[a]) + double(rng.Int(2, 50));
      r.dir = glm::dvec3(0.0);
      r.dir[a] = sign * std::ldexp(1.0, int(rng.Int(-10, 10)));
      f[1].rays.push_back(r);
    }
    {  // integer-ratio directions from lattice points: through edges and corners
      static const int kDirs[][3] = {{1, 1, 0}, {1, 1, 1}, {2, 1, 1}, {3, 2, 1}, {1, 2, 0}, {5, 3, 2}, {4, 4, 1}};
      const int* d0 = kDirs[rng.Int(0, 6)];
      int perm = int(rng.Int(0, 2));
      glm::dvec3 d;
      for (int a = 0; a < 3; ++a) d[(a + perm) % 3] = double(d0[a]) * (rng.Chance(0.5) ? 1 : -1);
      const Voxel& v = pick();
      double k = double(rng.Int(3, 100));
      Ray r;
      r.origin = glm::dvec3(v[0], v[1], v[2]) - k * d;
      r.dir = d * std::ldexp(1.0, int(rng.Int(-3, 3)));
      f[2].rays.push_back(r);
    }
    {  // grazing: in a face plane of an occupied voxel, or nearly
      const Voxel& v = pick();
      int a = int(rng.Int(0, 2));
      double plane = double(v[a]) + (rng.Chance(0.5) ? 0.0 : 1.0);
      glm::dvec3 target = Center(v);
      target[a] = plane;
      Ray r;
      glm::dvec3 u = unit();
      u[a] = 0;
      if (u.x == 0 && u.y == 0 && u.z == 0) u[(a + 1) % 3] = 1;
      r.origin = target + u * (extent * rng.Uniform(0.5, 2));
      r.origin[a] = plane;
      r.dir = target - r.origin;
      r.dir[a] = rng.Chance(0.5) ? (rng.Chance(0.5) ? 0.0 : -0.0) : std::ldexp(rng.Uniform(-1, 1), -40);
      f[3].rays.push_back(r);
    }
    {  // tiny, subnormal and signed-zero components
      static const double kTiny[] = {1e-300, 5e-324, -5e-324, 1e-30, -1e-200, 0.0, -0.0, 1e-17};
      glm::dvec3 target = Center(pick()) + glm::dvec3(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1));
      Ray r;
      r.origin = target + unit() * (extent * rng.Uniform(1, 3));
      r.dir = target - r.origin;
      int a = int(rng.Int(0, 2));
      r.dir[a] = kTiny[rng.Int(0, 7)];
      if (rng.Chance(0.3)) r.dir[(a + 1) % 3] = kTiny[rng.Int(0, 7)];
      if (r.dir.x == 0 && r.dir.y == 0 && r.dir.z == 0) r.dir[(a + 2) % 3] = 1;
      r.origin[a] = target[a];  // so the ray still reaches the object
      f[4].rays.push_back(r);
    }
    {  // far origins: 10^6 to 10^12 voxels away
      glm::dvec3 target = Center(pick()) + glm::dvec3(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5));
      Ray r;
      r.origin = target + unit() * std::pow(10.0, rng.Uniform(6, 12));
      r.dir = scale(target - r.origin);
      f[5].rays.push_back(r);
    }
  }
  for (RayFamily& fam : f) {
    fam.exact.reserve(fam.rays.size());
    for (const Ray& r : fam.rays) fam.exact.emplace_back(r);
    fam.expected.resize(fam.rays.size());
  }
  s->families = std::move(f);
}

StatusOr<std::unique_ptr<Scenario>> MakeScenario(const std::string& name, const std::string& shape,
                                                 int levels, int64_t offset, int brick_level, int n1,
                                                 int per_family, uint64_t seed) {
  auto sc = std::make_unique<Scenario>();
  sc->name = name;
  sc->levels = levels;
  sc->n1 = n1;
  VOX_ASSIGN_OR_RETURN(ShapeVolume shape_vol, GenerateShape(shape));
  std::vector<LeafPoint> pts;
  for (const LeafPoint& p : shape_vol.voxels) {
    LeafPoint q = p;
    q.x += uint64_t(offset);
    q.y += uint64_t(offset);
    q.z += uint64_t(offset);
    pts.push_back(q);
    sc->voxels.push_back({int64_t(q.x), int64_t(q.y), int64_t(q.z)});
  }
  VOX_ASSIGN_OR_RETURN(sc->tree, MemoryOctree::Build(std::move(pts), levels, brick_level));
  sc->ref = std::make_unique<Reference>(sc->voxels, levels);
  sc->description = "`" + shape + "` (" + std::to_string(sc->voxels.size()) + " voxels) at offset " +
                    std::to_string(offset) + " in a 2^" + std::to_string(levels) + " grid, split " +
                    std::to_string(n1) + "+" + std::to_string(levels - n1);
  MakeFamilies(sc.get(), per_family, seed);
  for (RayFamily& fam : sc->families)
    for (size_t i = 0; i < fam.rays.size(); ++i) fam.expected[i] = sc->ref->FirstHit(fam.exact[i]);
  return sc;
}

bool Fits(const TraversalVariant& v, int levels, int n1) {
  return std::max(n1, levels - n1) <= v.max_step_levels;
}

// The image's rays: the study camera's primary rays on a store, with the exact answers.
struct ImageRays {
  std::unique_ptr<Store> vol;
  OctreeView view;
  int n1 = 0;
  size_t voxels = 0;
  std::unique_ptr<Reference> ref;
  std::vector<Ray> rays;
  std::vector<ExactRay> exact;
  std::vector<RefHit> expected;
};

StatusOr<std::unique_ptr<ImageRays>> MakeImage(const std::string& store, int image) {
  auto im = std::make_unique<ImageRays>();
  VOX_ASSIGN_OR_RETURN(im->vol, OpenStudyStore(store));
  VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(im->vol->meta()));
  im->view = im->vol->view();
  std::vector<Voxel> voxels;
  VOX_RETURN_IF_ERROR(CollectVoxels(im->view, im->view.top, im->view.top[0], im->view.levels, 0, 0, 0, &voxels));
  im->voxels = voxels.size();
  im->ref = std::make_unique<Reference>(voxels, im->view.levels);
  im->n1 = DefaultFirstStepLevels(im->view.levels);
  const Camera cam = StudyCamera(image, image);
  for (int j = 0; j < image; ++j)
    for (int i = 0; i < image; ++i) {
      WorldRay w = cam.PixelRay(i + 0.5, j + 0.5);
      Ray r{xf.WorldToGrid(w.origin), xf.world_to_grid_linear * w.dir};
      im->rays.push_back(r);
      im->exact.emplace_back(r);
    }
  for (const ExactRay& er : im->exact) im->expected.push_back(im->ref->FirstHit(er));
  fprintf(stderr, "precision: references ready (%zu store voxels, %zu pixels)\n", im->voxels, im->rays.size());
  return im;
}

struct Result {
  std::vector<std::vector<uint64_t>> refused;  // [scene][family]
  std::vector<uint64_t> scene_rays, scene_refused;
  std::vector<std::vector<double>> pass_seconds;  // [scene] timed passes over random rays
  bool image_ok = false;
  uint64_t pix_refused = 0, pix_other_voxel = 0;
  std::vector<bool> fits;
  std::string error;
  std::vector<std::unique_ptr<AnyTracer>> tracers;  // [scene], null where the variant does not fit
};

// Checks one variant on every scenario's families and on the image; appends the first refused
// rays (at most 5 per scenario) to `log`.
Result CheckVariant(const TraversalVariant& tv, const std::vector<std::unique_ptr<Scenario>>& scenes,
                    const ImageRays& im, std::string* log) {
  Result R;
  R.refused.assign(scenes.size(), std::vector<uint64_t>(6, 0));
  R.scene_rays.assign(scenes.size(), 0);
  R.scene_refused.assign(scenes.size(), 0);
  R.pass_seconds.assign(scenes.size(), {});
  R.tracers.resize(scenes.size());
  for (size_t s = 0; s < scenes.size(); ++s) {
    const Scenario& sc = *scenes[s];
    R.fits.push_back(Fits(tv, sc.levels, sc.n1));
    if (!R.fits.back()) continue;
    auto t = tv.create(sc.tree->view(), sc.n1);
    if (!t.ok()) {
      R.fits.back() = false;
      R.error += tv.name + " on " + sc.name + ": " + t.status().ToString() + "; ";
      continue;
    }
    R.tracers[s] = std::move(t).value();
    for (size_t fi = 0; fi < sc.families.size(); ++fi) {
      const RayFamily& fam = sc.families[fi];
      for (size_t i = 0; i < fam.rays.size(); ++i) {
        auto got = R.tracers[s]->FirstHit(fam.rays[i], nullptr);
        std::string why = got.ok() ? CheckFirstHit(*sc.ref, fam.exact[i], fam.expected[i], *got)
                                   : "tracer error " + got.status().ToString();
        bool ok = why.empty();
        if (!ok && R.scene_refused[s] < 5)
          *log += tv.name + " | " + sc.name + " | " + fam.name + " | " + why +
                  (why.find("[origin") == std::string::npos ? " [" + testing::RayString(fam.rays[i]) + "]"
                                                            : std::string()) +
                  "\n";
        R.refused[s][fi] += !ok;
        R.scene_refused[s] += !ok;
        ++R.scene_rays[s];
      }
    }
  }
  if (Fits(tv, im.view.levels, im.n1)) {
    auto t = tv.create(im.view, im.n1);
    if (t.ok()) {
      R.image_ok = true;
      for (size_t i = 0; i < im.rays.size(); ++i) {
        auto got = (*t)->FirstHit(im.rays[i], nullptr);
        bool ok = got.ok() && CheckFirstHit(*im.ref, im.exact[i], im.expected[i], *got).empty();
        R.pix_refused += !ok;
        const RefHit& e = im.expected[i];
        bool same = got.ok() && got->has_value() == e.hit && (!e.hit || testing::ToVoxel(**got) == e.voxel);
        R.pix_other_voxel += !same;
      }
    }
  }
  fprintf(stderr, "precision: %s checked\n", tv.name.c_str());
  return R;
}

// Timing: passes over each scene's random rays, all variants side by side in every round. A
// pass repeats the ray set until the default variant's pass takes about 50 ms, so scheduler
// noise averages out within a pass.
void TimeVariants(const std::vector<std::unique_ptr<Scenario>>& scenes, int rounds, std::vector<Result>* res) {
  auto pass = [&](size_t v, size_t s, int repeat) {
    const RayFamily& fam = scenes[s]->families[0];
    uint64_t hits = 0;
    auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < repeat; ++k)
      for (const Ray& r : fam.rays) {
        auto got = (*res)[v].tracers[s]->FirstHit(r, nullptr);
        hits += got.ok() && got->has_value();
      }
    double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (hits == uint64_t(-1)) fprintf(stderr, " ");  // keeps the loop observable
    return sec / (double(repeat) * double(fam.rays.size()));
  };
  std::vector<int> repeat(scenes.size(), 1);
  for (size_t s = 0; s < scenes.size(); ++s)
    if ((*res)[0].tracers[s]) {
      double per_ray = pass(0, s, 1);
      repeat[s] = std::clamp(int(0.05 / (per_ray * double(scenes[s]->families[0].rays.size()))), 1, 200);
    }
  for (int round = 0; round < rounds + 2; ++round)
    for (size_t s = 0; s < scenes.size(); ++s)
      for (size_t k = 0; k < res->size(); ++k) {
        size_t v = (k + size_t(round)) % res->size();
        if ((*res)[v].tracers[s]) (*res)[v].pass_seconds[s].push_back(pass(v, s, repeat[s]));
      }
}

}  // namespace

StatusOr<nlohmann::json> RunPrecision(const PrecisionOptions& o) {
  const std::vector<TraversalVariant> variants = TraversalVariants();
  if (variants.empty()) return InternalError("TraversalVariants() is empty");
  std::vector<std::unique_ptr<Scenario>> scenes;
  // A: an ordinary grid and split. B: the same shell deep in a 2^24 grid,
  // 12+12 (long DDA runs in both steps). C: at the far corner of OpenVDB's
  // whole index space, 2^40, split 20+20 (the largest steps vox traces).
  fprintf(stderr, "precision: building scenarios and the exact reference answers\n");
  VOX_ASSIGN_OR_RETURN(auto a, MakeScenario("A", "sphere:256", 8, 0, 3, 6, o.per_family, 11));
  scenes.push_back(std::move(a));
  VOX_ASSIGN_OR_RETURN(auto b, MakeScenario("B", "sphere:256", 24, (int64_t(1) << 23) - 128, 12, 12, o.per_family, 12));
  scenes.push_back(std::move(b));
  VOX_ASSIGN_OR_RETURN(auto c, MakeScenario("C", "sphere:128", 40, (int64_t(1) << 40) - 200, 20, 20,
                                            o.per_family / 2, 13));
  scenes.push_back(std::move(c));
  VOX_ASSIGN_OR_RETURN(auto im, MakeImage(o.store, o.image));
  // The first refused rays of each variant and scenario, to reproduce them.
  std::string refused_log =
      "# First refused rays per variant and scenario (at most 5 each), C99 hex floats\n"
      "# variant | scenario | family | reason\n";
  std::vector<Result> res;
  for (const TraversalVariant& tv : variants) res.push_back(CheckVariant(tv, scenes, *im, &refused_log));
  TimeVariants(scenes, o.rounds, &res);

  nlohmann::json out;
  out["image"] = {{"size", o.image}, {"voxels", im->voxels}, {"split", std::to_string(im->n1) + "+" +
                  std::to_string(im->view.levels - im->n1)}, {"pixels", im->rays.size()}};
  for (const auto& sc : scenes) {
    nlohmann::json j = {{"name", sc->name}, {"description", sc->description}};
    for (const auto& fam : sc->families) j["families"].push_back({{"name", fam.name}, {"rays", fam.rays.size()}});
    out["scenarios"].push_back(j);
  }
  for (size_t v = 0; v < variants.size(); ++v) {
    const Result& R = res[v];
    const TraversalVariant& tv = variants[v];
    nlohmann::json j = {{"name", tv.name}, {"family", tv.family}, {"word", tv.word_bits},
                        {"frac", tv.frac_bits}, {"real", tv.real}, {"error", R.error}};
    for (size_t s = 0; s < scenes.size(); ++s) {
      nlohmann::json sj = {{"fits", bool(R.fits[s])}, {"rays", R.scene_rays[s]}, {"refused", R.scene_refused[s]},
                           {"pass_seconds", R.pass_seconds[s]}};
      if (R.fits[s]) sj["refused_by_family"] = R.refused[s];
      j["scenarios"].push_back(sj);
    }
    if (R.image_ok) j["image"] = {{"refused", R.pix_refused}, {"other_voxel", R.pix_other_voxel}};
    out["variants"].push_back(j);
  }
  out["refused_log"] = refused_log;
  return out;
}

}  // namespace vox::bench

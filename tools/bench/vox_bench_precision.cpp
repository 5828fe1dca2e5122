// vox-bench part 2: precision against time. Every traversal variant of
// core/variants.h traces the same rays over the same octrees; each first hit
// is checked against the exact GMP reference of the core tests
// (tests/core/reference.h) with its acceptance rule (an ambiguous reference
// answer accepts any voxel the ray touches no later), on random rays and on
// the hard-case families, and on the primary rays of a rendered image.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

#include "core/shapes.h"
#include "render/grid_transform.h"
#include "tests/core/test_util.h"
#include "tools/bench/vox_bench.h"
#include "tools/study/reference.h"
#include "tools/study/variants.h"

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
  sc->description = Fmt("`%s` (%zu voxels) at offset %lld in a 2^%d grid, split %d+%d", shape.c_str(),
                        sc->voxels.size(), (long long)offset, levels, n1, levels - n1);
  MakeFamilies(sc.get(), per_family, seed);
  for (RayFamily& fam : sc->families)
    for (size_t i = 0; i < fam.rays.size(); ++i) fam.expected[i] = sc->ref->FirstHit(fam.exact[i]);
  return sc;
}

bool Fits(const TraversalVariant& v, int levels, int n1) {
  return std::max(n1, levels - n1) <= v.max_step_levels;
}

}  // namespace

Status RunPrecisionPart(const RunContext& ctx, std::string* report) {
  const std::vector<TraversalVariant> variants = TraversalVariants();
  if (variants.empty()) return InternalError("TraversalVariants() is empty");
  const int per_family = ctx.quick ? 2000 : 10000;
  std::vector<std::unique_ptr<Scenario>> scenes;
  // A: an ordinary grid and split. B: the same shell deep in a 2^24 grid,
  // 12+12 (long DDA runs in both steps). C: at the far corner of OpenVDB's
  // whole index space, 2^40, split 20+20 (the largest steps vox traces).
  fprintf(stderr, "precision: building scenarios and the exact reference answers\n");
  VOX_ASSIGN_OR_RETURN(auto a, MakeScenario("A", "sphere:256", 8, 0, 3, 6, per_family, 11));
  scenes.push_back(std::move(a));
  VOX_ASSIGN_OR_RETURN(auto b, MakeScenario("B", "sphere:256", 24, (int64_t(1) << 23) - 128, 12, 12, per_family, 12));
  scenes.push_back(std::move(b));
  VOX_ASSIGN_OR_RETURN(auto c, MakeScenario("C", "sphere:128", 40, (int64_t(1) << 40) - 200, 20, 20,
                                            per_family / 2, 13));
  scenes.push_back(std::move(c));

  // The image: primary rays of the study camera on a small level-set sphere store.
  const int image = ctx.quick ? 192 : 384;
  VOX_ASSIGN_OR_RETURN(std::string vdb, EnsureSphereVdb(ctx, 240, 3.0));
  VOX_ASSIGN_OR_RETURN(std::string store, EnsureStore(ctx, vdb));
  VOX_ASSIGN_OR_RETURN(auto vol, OpenStore(store));
  VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(vol->meta()));
  const OctreeView store_view = vol->view();
  std::vector<Voxel> store_voxels;
  VOX_RETURN_IF_ERROR(CollectVoxels(store_view, store_view.top, store_view.top[0], store_view.levels, 0, 0, 0,
                                    &store_voxels));
  Reference store_ref(store_voxels, store_view.levels);
  const int store_n1 = DefaultFirstStepLevels(store_view.levels);
  const Camera cam = StudyCamera(image, image);
  std::vector<Ray> pix_rays;
  std::vector<ExactRay> pix_exact;
  std::vector<RefHit> pix_expected;
  for (int j = 0; j < image; ++j)
    for (int i = 0; i < image; ++i) {
      WorldRay w = cam.PixelRay(i + 0.5, j + 0.5);
      Ray r{xf.WorldToGrid(w.origin), xf.world_to_grid_linear * w.dir};
      pix_rays.push_back(r);
      pix_exact.emplace_back(r);
    }
  for (const ExactRay& er : pix_exact) pix_expected.push_back(store_ref.FirstHit(er));
  fprintf(stderr, "precision: references ready (%zu store voxels, %zu pixels)\n", store_voxels.size(),
          pix_rays.size());

  struct Result {
    std::vector<std::vector<uint64_t>> refused;  // [scene][family]
    std::vector<uint64_t> scene_rays, scene_refused;
    std::vector<std::vector<double>> pass_seconds;  // [scene] timed passes over random rays
    bool image_ok = false;
    uint64_t pix_refused = 0, pix_other_voxel = 0;
    std::vector<bool> fits;
    std::string error;
  };
  std::vector<Result> res(variants.size());
  // The first refused rays of each variant and scenario, to reproduce them.
  std::string refused_log =
      "# First refused rays per variant and scenario (at most 5 each), C99 hex floats\n"
      "# variant | scenario | family | reason\n";
  std::vector<std::vector<std::unique_ptr<AnyTracer>>> tracers(variants.size());
  for (size_t v = 0; v < variants.size(); ++v) {
    Result& R = res[v];
    R.refused.assign(scenes.size(), std::vector<uint64_t>(6, 0));
    R.scene_rays.assign(scenes.size(), 0);
    R.scene_refused.assign(scenes.size(), 0);
    R.pass_seconds.assign(scenes.size(), {});
    tracers[v].resize(scenes.size());
    for (size_t s = 0; s < scenes.size(); ++s) {
      Scenario& sc = *scenes[s];
      R.fits.push_back(Fits(variants[v], sc.levels, sc.n1));
      if (!R.fits.back()) continue;
      auto t = variants[v].create(sc.tree->view(), sc.n1);
      if (!t.ok()) {
        R.fits.back() = false;
        R.error += variants[v].name + " on " + sc.name + ": " + t.status().ToString() + "; ";
        continue;
      }
      tracers[v][s] = std::move(t).value();
      for (size_t fi = 0; fi < sc.families.size(); ++fi) {
        RayFamily& fam = sc.families[fi];
        for (size_t i = 0; i < fam.rays.size(); ++i) {
          auto got = tracers[v][s]->FirstHit(fam.rays[i], nullptr);
          std::string why = got.ok() ? CheckFirstHit(*sc.ref, fam.exact[i], fam.expected[i], *got)
                                     : "tracer error " + got.status().ToString();
          bool ok = why.empty();
          if (!ok && R.scene_refused[s] < 5)
            refused_log += variants[v].name + " | " + sc.name + " | " + fam.name + " | " + why +
                           (why.find("[origin") == std::string::npos
                                ? " [" + testing::RayString(fam.rays[i]) + "]"
                                : std::string()) +
                           "\n";
          R.refused[s][fi] += !ok;
          R.scene_refused[s] += !ok;
          ++R.scene_rays[s];
        }
      }
    }
    if (Fits(variants[v], store_view.levels, store_n1)) {
      auto t = variants[v].create(store_view, store_n1);
      if (t.ok()) {
        R.image_ok = true;
        for (size_t i = 0; i < pix_rays.size(); ++i) {
          auto got = (*t)->FirstHit(pix_rays[i], nullptr);
          bool ok = got.ok() && CheckFirstHit(store_ref, pix_exact[i], pix_expected[i], *got).empty();
          R.pix_refused += !ok;
          const RefHit& e = pix_expected[i];
          bool same = got.ok() && got->has_value() == e.hit &&
                      (!e.hit || testing::ToVoxel(**got) == e.voxel);
          R.pix_other_voxel += !same;
        }
      }
    }
    fprintf(stderr, "precision: %s checked\n", variants[v].name.c_str());
  }
  // Timing: passes over each scene's random rays, all variants side by side
  // in every round. A pass repeats the ray set until the default variant's
  // pass takes about 50 ms, so scheduler noise averages out within a pass.
  auto pass = [&](size_t v, size_t s, int repeat) {
    const RayFamily& fam = scenes[s]->families[0];
    uint64_t hits = 0;
    auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < repeat; ++k)
      for (const Ray& r : fam.rays) {
        auto got = tracers[v][s]->FirstHit(r, nullptr);
        hits += got.ok() && got->has_value();
      }
    double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (hits == uint64_t(-1)) fprintf(stderr, " ");  // keeps the loop observable
    return sec / (double(repeat) * double(fam.rays.size()));
  };
  std::vector<int> repeat(scenes.size(), 1);
  for (size_t s = 0; s < scenes.size(); ++s)
    if (tracers[0][s]) {
      double per_ray = pass(0, s, 1);
      repeat[s] = std::clamp(int(0.05 / (per_ray * double(scenes[s]->families[0].rays.size()))), 1, 200);
    }
  for (int round = 0; round < ctx.rounds + 2; ++round)
    for (size_t s = 0; s < scenes.size(); ++s)
      for (size_t k = 0; k < variants.size(); ++k) {
        size_t v = (k + size_t(round)) % variants.size();
        if (!tracers[v][s]) continue;
        res[v].pass_seconds[s].push_back(pass(v, s, repeat[s]));
      }

  // Tables.
  Table table({"variant", "family", "word", "frac", "real", "ns / ray (A)", "time / default (A)",
               "ns / ray (C)", "refused A", "refused B", "refused C", "refused, all", "image pixels refused",
               "image pixels with another voxel"});
  std::vector<std::string> detail_cols = {"variant"};
  for (const auto& sc : scenes)
    for (const auto& fam : sc->families) detail_cols.push_back(sc->name + ": " + fam.name);
  Table detail(detail_cols);
  std::map<std::string, Series> by_family;
  const uint64_t total_rays_all = [&] {
    uint64_t n = 0;
    for (const auto& sc : scenes)
      for (const auto& fam : sc->families) n += fam.rays.size();
    return n;
  }();
  const double zero_at = 0.5 / double(total_rays_all);
  auto rate = [](uint64_t bad, uint64_t n) { return n ? double(bad) / double(n) : std::nan(""); };
  auto pct = [&](uint64_t bad, uint64_t n) {
    return n ? Fmt("%.3g%% (%llu)", 100.0 * rate(bad, n), (unsigned long long)bad) : std::string("n/a");
  };
  for (size_t v = 0; v < variants.size(); ++v) {
    const Result& R = res[v];
    const TraversalVariant& tv = variants[v];
    auto ns = [&](size_t s) { return R.pass_seconds[s].empty() ? std::nan("") : 1e9 * Median(R.pass_seconds[s]); };
    std::vector<double> ratio;
    for (size_t i = 0; i < R.pass_seconds[0].size() && i < res[0].pass_seconds[0].size(); ++i)
      ratio.push_back(R.pass_seconds[0][i] / res[0].pass_seconds[0][i]);
    uint64_t all_bad = 0, all_n = 0;
    for (size_t s = 0; s < scenes.size(); ++s)
      if (R.fits[s]) {
        all_bad += R.scene_refused[s];
        all_n += R.scene_rays[s];
      }
    std::vector<std::string> row = {tv.name, tv.family, tv.word_bits ? std::to_string(tv.word_bits) : "-",
                                    tv.word_bits ? std::to_string(tv.frac_bits) : "-", tv.real,
                                    std::isnan(ns(0)) ? "n/a" : Fmt("%.0f", ns(0)),
                                    ratio.empty() ? "n/a" : Fmt("%.2f", Median(ratio)),
                                    std::isnan(ns(2)) ? "n/a" : Fmt("%.0f", ns(2))};
    for (size_t s = 0; s < scenes.size(); ++s)
      row.push_back(R.fits[s] ? pct(R.scene_refused[s], R.scene_rays[s]) : "n/a (step too deep)");
    row.push_back(pct(all_bad, all_n));
    row.push_back(R.image_ok ? pct(R.pix_refused, pix_rays.size()) : "n/a");
    row.push_back(R.image_ok ? pct(R.pix_other_voxel, pix_rays.size()) : "n/a");
    table.Add(row);
    std::vector<std::string> drow = {tv.name};
    for (size_t s = 0; s < scenes.size(); ++s)
      for (size_t fi = 0; fi < scenes[s]->families.size(); ++fi)
        drow.push_back(R.fits[s] ? std::to_string(R.refused[s][fi]) : "n/a");
    detail.Add(drow);
    if (!std::isnan(ns(0)) && all_n) {
      Series& ser = by_family[tv.family];
      ser.name = tv.family;
      ser.line = false;
      double r = rate(all_bad, all_n);
      ser.points.push_back({ns(0), r > 0 ? r : zero_at});
      ser.labels.push_back(tv.name);
    }
  }
  std::string scen;
  for (const auto& sc : scenes) {
    scen += "- **" + sc->name + "**: " + sc->description + "; rays per family:";
    for (const auto& fam : sc->families) scen += Fmt(" %s %zu,", fam.name.c_str(), fam.rays.size());
    scen.back() = '.';
    scen += "\n";
  }
  std::string errors;
  for (const auto& R : res) errors += R.error;
  std::string notes =
      "Scenarios (grid coordinates; the rays are aimed at occupied voxels of each):\n\n" + scen +
      Fmt("- **image**: the %dx%d primary rays of the study camera on the level-set sphere 240 voxels "
          "across (store %s, %zu voxels, split %d+%d).\n\n",
          image, image, store.c_str(), store_voxels.size(), store_n1, store_view.levels - store_n1) +
      "`refused`: first hits the exact reference (tests/core/reference.h, GMP rationals) does not "
      "accept: a different voxel, a miss or a spurious hit, where an ambiguous reference answer "
      "(the ray touches another occupied voxel's closed cube no later than the first one it meets) "
      "accepts any voxel touched no later. `image pixels with another voxel`: pixels whose hit voxel "
      "differs from the reference's, accepted or not. `ns / ray`: single thread, median of passes "
      "over the scenario's random rays (all variants one after another in each round); `time / "
      "default`: median of per-round ratios to the first variant. `n/a (step too deep)`: the variant "
      "cannot hold a step of that many levels. Per family: [precision_families.md](precision_families.md); the first refused rays: "
      "[precision_refused.txt](precision_refused.txt).\n" +
      (errors.empty() ? "" : "\nRefused at creation: " + errors + "\n");
  VOX_RETURN_IF_ERROR(WriteFile(ctx.out_dir + "/precision_refused.txt", refused_log));
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "precision", "Precision against time", table, notes));
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "precision_families", "Refused first hits per scenario and ray family",
                                 detail, "Counts of refused first hits; scenarios as in [precision.md](precision.md).\n"));
  PlotSpec ps;
  ps.title = "Precision against time (traversal variants)";
  ps.x_label = "ns per ray (scenario A, one thread)";
  ps.y_label = Fmt("first hits refused by the exact reference (0 drawn at %.0e)", zero_at);
  ps.log_x = ps.log_y = true;
  ps.width = 900;
  ps.height = 560;
  std::vector<Series> ser;
  for (auto& [k, s] : by_family) ser.push_back(s);
  VOX_RETURN_IF_ERROR(WriteFile(ctx.out_dir + "/precision.svg", SvgPlot(ps, ser)));
  *report += "## 2. Precision against time\n\n" + Provenance(ctx) + "\n" + table.Markdown() + "\n" + notes +
             "\n![error rate against time per ray](precision.svg)\n\n";
  return OkStatus();
}

}  // namespace vox::bench

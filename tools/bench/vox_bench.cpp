// vox-bench: what accuracy costs in time (docs/accuracy.md). Runs, in one process,
//   1. paper:      the paper's figures 7 and 8: single step against two steps
//                  with 4..7 first-step levels, one store per grid, one camera;
//   2. precision:  every traversal variant (core/variants.h): time per ray and
//                  first hits refused by the exact reference;
//   3. resolution: one object ingested at several resolutions: time, store
//                  size, silhouette and shading against the finest and against
//                  vdb_render's sub-voxel intersection;
//   4. effects:    visibility, shading, shadows, reflection, refraction;
//   5. peer:       vox against vdb_render, same scenes, camera and threads;
// and writes Markdown tables, CSV and SVG plots into --out.
//
//   vox-bench [--quick] [--out DIR] [--work DIR] [--threads N] [--rounds N]
//             [--parts paper,precision,resolution,effects,peer] [--grids 1024,2048]
//             [--images 256,512,1024]
#include "tools/bench/vox_bench.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <set>
#include <sstream>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "render/tiles.h"

namespace vox::bench {

// ------------------------------------------------------------ shared helpers

Camera StudyCamera(int width, int height) {
  Camera c;
  c.position = {0, 0, 3};
  c.look_at = {0, 0, 0};
  c.up = {0, 1, 0};
  c.fov_deg = 40;
  c.width = width;
  c.height = height;
  c.projection = Projection::kPerspective;
  (void)c.Finalize("study camera");
  return c;
}

std::string VdbCameraArgs(int width, int height) {
  return Fmt("-translate 0,0,3 -lookat 0,0,0 -up 0,1,0 -fov 40 -res %dx%d", width, height);
}

Scene DiffuseScene() {
  auto s = ParseScene(R"({"lights":[{"type":"directional","direction":[-0.3,-0.5,-1],"shadows":false}],
                          "material":{"specular":0}})",
                      "diffuse scene");
  return s.ok() ? *s : Scene{};
}

StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& dir) {
  OpenOptions oo;
  oo.cache_bytes = size_t(3) << 30;
  return Store::Open(dir, oo);
}

StatusOr<FrameStats> TimeFrame(const Renderer& r, int threads) {
  FrameOptions fo;
  fo.threads = threads;
  FrameStats st;
  VOX_RETURN_IF_ERROR(RenderFrame(r, fo, &st));
  return st;
}

StatusOr<Image> RenderImage(const Renderer& r) {
  const Camera& cam = r.camera();
  TileLayout layout(cam.width, cam.height, 64);
  Image im;
  im.width = cam.width;
  im.height = cam.height;
  im.rgb.assign(size_t(cam.width) * cam.height * 3, 0.0f);
  im.mask.assign(size_t(cam.width) * cam.height, 0);
  std::mutex mu;
  Status first_error;
  tbb::parallel_for(size_t(0), layout.order().size(), [&](size_t i) {
    const TileRect& rect = layout.order()[i];
    TileBuffer buf;
    buf.Allocate(64, r.layers());
    RenderCounters counters;
    Status s = r.RenderTile(rect, &buf, &counters);
    if (!s.ok()) {
      std::lock_guard<std::mutex> lock(mu);
      if (first_error.ok()) first_error = s;
      return;
    }
    for (int y = 0; y < rect.h; ++y)
      for (int x = 0; x < rect.w; ++x) {
        size_t p = size_t(rect.y0 + y) * cam.width + (rect.x0 + x);
        for (int c = 0; c < 3; ++c) im.rgb[3 * p + c] = *buf.at(kChR + c, x, y);
        im.mask[p] = *buf.at(kChA, x, y) > 0.5f;
      }
  });
  if (!first_error.ok()) return first_error;
  return im;
}

Status WriteTable(const RunContext& ctx, const std::string& name, const std::string& title,
                  const Table& table, const std::string& notes) {
  std::string md = "# " + title + "\n\n" + Provenance(ctx) + "\n" + table.Markdown();
  if (!notes.empty()) md += "\n" + notes;
  md += "\nCSV: [" + name + ".csv](" + name + ".csv)\n";
  VOX_RETURN_IF_ERROR(WriteFile(ctx.out_dir + "/" + name + ".md", md));
  return WriteFile(ctx.out_dir + "/" + name + ".csv", table.Csv());
}

namespace {

std::string Secs(double s) { return s < 0.1 ? Fmt("%.4f", s) : Fmt("%.3f", s); }
std::string Ratio(double r) { return Fmt("%.2fx", r); }
double PerRay(uint64_t v, uint64_t rays) { return rays ? double(v) / double(rays) : 0.0; }

// vdb_render's own "ray-tracing ... completed in X sec" time from -v output.
StatusOr<double> VdbRayTracingSeconds(const std::string& out) {
  size_t p = out.find("ray-tracing");
  if (p == std::string::npos) return InternalError("vdb_render -v printed no ray-tracing time:\n" + out);
  size_t q = out.find("completed in", p);
  if (q == std::string::npos) return InternalError("vdb_render -v printed no completion time:\n" + out);
  return std::atof(out.c_str() + q + 12);
}

}  // namespace

// ------------------------------------------------------------ 1. paper

Status RunPaperPart(const RunContext& ctx, std::string* report) {
  std::vector<int> grids = ctx.quick ? std::vector<int>{1024, 2048} : std::vector<int>{1024, 2048, 4096};
  std::vector<int> images =
      ctx.quick ? std::vector<int>{256, 512, 1024} : std::vector<int>{256, 512, 1024, 2048};
  if (!ctx.grids.empty()) grids = ctx.grids;
  if (!ctx.images.empty()) images = ctx.images;
  const std::vector<int> first_levels = {4, 5, 6, 7};
  Table main({"image", "grid", "levels", "single step (s)", "4+ (s)", "5+ (s)", "6+ (s)", "7+ (s)",
              "best split", "single / best", "single / 6+", "first hits only: single / best"});
  Table stats({"image", "grid", "traversal", "median (s)", "first hits only (s)", "ns per ray (x threads)",
               "moves / ray",
               "driving / ray", "passive / ray", "skips / ray", "cells / ray", "transitions / ray",
               "brick fetches / ray", "hit pixels"});
  std::vector<Series> plot;
  struct Finding {
    int grid, image;
    double best_speedup, speedup6;
    int best_n1;
    double trav_speedup, moves_single, moves_best, ns_single, ns_best;
  };
  std::vector<Finding> findings;

  for (int grid : grids) {
    // A thin shell for the biggest grids: a sphere 15/16 of the grid across.
    const double band = grid >= 8192 ? 1.5 : 3.0;  // vdb_tool needs > 1
    VOX_ASSIGN_OR_RETURN(std::string vdb, EnsureSphereVdb(ctx, grid * 15 / 16, band));
    VOX_ASSIGN_OR_RETURN(std::string store, EnsureStore(ctx, vdb));
    VOX_ASSIGN_OR_RETURN(auto vol, OpenStore(store));
    const int levels = vol->meta().levels;
    fprintf(stderr, "paper: grid %d (%s, %d levels, %llu voxels)\n", grid, store.c_str(), levels,
            (unsigned long long)vol->meta().voxel_count);
    for (int image : images) {
      const Camera cam = StudyCamera(image, image);
      const Scene scene = DiffuseScene();
      std::vector<int> configs = {levels};  // single step first
      for (int n1 : first_levels)
        if (n1 < levels && levels - n1 <= kMaxStepLevels) configs.push_back(n1);
      if (configs.size() < 2) {
        fprintf(stderr, "paper: grid %d has %d levels: no split with 4..7 first-step levels\n", grid, levels);
        continue;
      }
      std::vector<std::unique_ptr<Renderer>> rs;
      for (int n1 : configs) {
        RenderOptions ro;
        ro.n1 = n1;
        // The paper's traversal: no beam start distances (vox's own, they
        // start every primary ray next to the surface whatever the split).
        ro.beam = false;
        VOX_ASSIGN_OR_RETURN(auto r, Renderer::Create(vol.get(), cam, scene, ro));
        rs.push_back(std::move(r));
      }
      std::vector<std::vector<double>> t(configs.size()), tt(configs.size());
      std::vector<FrameStats> last(configs.size());
      // The same primary rays traced for their first hit only (no shading,
      // attributes or tiles): the traversal's share of the frame.
      VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(vol->meta()));
      std::vector<Ray> rays(size_t(image) * image);
      for (int j = 0; j < image; ++j)
        for (int i = 0; i < image; ++i) {
          WorldRay w = cam.PixelRay(i + 0.5, j + 0.5);
          rays[size_t(j) * image + i] = Ray{xf.WorldToGrid(w.origin), xf.world_to_grid_linear * w.dir};
        }
      std::vector<RenderTracer> tracers;
      for (int n1 : configs) {
        VOX_ASSIGN_OR_RETURN(RenderTracer tr, RenderTracer::Create(vol->view(), n1));
        tracers.push_back(tr);
      }
      tbb::task_arena arena(ctx.threads);
      auto trace_pass = [&](const RenderTracer& tr) {
        std::atomic<uint64_t> hits{0};
        auto t0 = std::chrono::steady_clock::now();
        arena.execute([&] {
          tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 1024), [&](const tbb::blocked_range<size_t>& br) {
            uint64_t h = 0;
            for (size_t i = br.begin(); i != br.end(); ++i) {
              auto got = tr.FirstHit(rays[i]);
              h += got.ok() && got->has_value();
            }
            hits += h;
          });
        });
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      };
      // Warm-up: pages in every brick the camera sees.
      for (size_t c = 0; c < rs.size(); ++c) VOX_RETURN_IF_ERROR(TimeFrame(*rs[c], ctx.threads).status());
      for (int round = 0; round < ctx.rounds; ++round)
        for (size_t k = 0; k < rs.size(); ++k) {
          size_t c = (k + size_t(round)) % rs.size();  // rotate the order per round
          VOX_ASSIGN_OR_RETURN(FrameStats st, TimeFrame(*rs[c], ctx.threads));
          t[c].push_back(st.render_seconds);
          last[c] = st;
        }
      for (int round = 0; round < ctx.rounds; ++round)
        for (size_t k = 0; k < rs.size(); ++k) {
          size_t c = (k + size_t(round)) % rs.size();
          tt[c].push_back(trace_pass(tracers[c]));
        }
      std::vector<double> med(configs.size());
      for (size_t c = 0; c < configs.size(); ++c) med[c] = Median(t[c]);
      size_t best = 1;
      for (size_t c = 1; c < configs.size(); ++c)
        if (med[c] < med[best]) best = c;
      auto speedup = [&](size_t c) {
        std::vector<double> r;
        for (int i = 0; i < ctx.rounds; ++i) r.push_back(t[0][size_t(i)] / t[c][size_t(i)]);
        return Median(r);
      };
      std::vector<std::string> row = {Fmt("%d^2", image), Fmt("%d^3", grid), std::to_string(levels),
                                      Secs(med[0])};
      double s6 = std::nan("");
      for (int n1 : first_levels) {
        auto it = std::find(configs.begin() + 1, configs.end(), n1);
        if (it == configs.end()) {
          row.push_back("n/a");
          continue;
        }
        size_t c = size_t(it - configs.begin());
        row.push_back(c == best ? "**" + Secs(med[c]) + "**" : Secs(med[c]));
        if (n1 == 6) s6 = speedup(c);
      }
      row.push_back(Fmt("%d+%d", configs[best], levels - configs[best]));
      row.push_back(Ratio(speedup(best)));
      row.push_back(std::isnan(s6) ? "n/a" : Ratio(s6));
      double trav_speedup;
      {
        std::vector<double> r;
        for (int i = 0; i < ctx.rounds; ++i) r.push_back(tt[0][size_t(i)] / tt[best][size_t(i)]);
        trav_speedup = Median(r);
        row.push_back(Ratio(trav_speedup));
      }
      main.Add(row);
      const double rays0 = double(last[0].counters.trace.rays), raysb = double(last[best].counters.trace.rays);
      findings.push_back({grid, image, speedup(best), s6, configs[best], trav_speedup,
                          double(last[0].counters.trace.total_moves()) / rays0,
                          double(last[best].counters.trace.total_moves()) / raysb,
                          1e9 * med[0] * ctx.threads / rays0, 1e9 * med[best] * ctx.threads / raysb});
      Series s;
      s.name = Fmt("%d^3, %d^2", grid, image);
      for (size_t c = 1; c < configs.size(); ++c) s.points.push_back({double(configs[c]), speedup(c)});
      plot.push_back(s);
      for (size_t c = 0; c < configs.size(); ++c) {
        const RenderCounters& rc = last[c].counters;
        const uint64_t rays = rc.trace.rays;
        stats.Add({Fmt("%d^2", image), Fmt("%d^3", grid),
                   c == 0 ? "single step" : Fmt("%d+%d", configs[c], levels - configs[c]), Secs(med[c]),
                   Secs(Median(tt[c])),
                   Fmt("%.0f", 1e9 * med[c] * ctx.threads / double(rays)),
                   Fmt("%.1f", PerRay(rc.trace.total_moves(), rays)),
                   Fmt("%.1f", PerRay(rc.trace.driving_moves, rays)),
                   Fmt("%.1f", PerRay(rc.trace.passive_moves, rays)),
                   Fmt("%.1f", PerRay(rc.trace.skips, rays)),
                   Fmt("%.1f", PerRay(rc.trace.cells_visited, rays)),
                   Fmt("%.2f", PerRay(rc.trace.transitions, rays)),
                   Fmt("%.3f", PerRay(rc.trace.brick_fetches, rays)), std::to_string(rc.hit_pixels)});
      }
      fprintf(stderr, "paper: %d^2 on %d^3: single %.3f s, best %d+%d %.3f s (%.2fx)\n", image, grid,
              med[0], configs[best], levels - configs[best], med[best], speedup(best));
    }
  }
  std::string notes =
      "Scene: a level-set sphere (vdb_tool -sphere, radius 1, 15/16 of the grid across, narrow band "
      "3 voxels; 1.5 voxels for grids of 8192 and up) ingested once per grid with `auto` levels; the "
      "render-time split varies (RenderOptions::n1; single step = all levels in the first step), "
      "without vox's beam start distances (RenderOptions::beam off: the paper's walk from the "
      "occupied box). "
      "Camera at (0,0,3) looking at the centre, 40 degrees; one directional light, no shadows. "
      "Times: wall-clock render of the whole frame (no EXR write), warm brick cache, median over "
      "rounds; ratios are medians of per-round ratios (single step time / two-step time of the "
      "same round). Bold: the fastest split. `first hits only`: the same primary rays traced by the "
      "render tracer for their first hit, nothing else (no shading, attributes, tiles), same threads. Counters: [paper_stats.md](paper_stats.md).\n";
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "paper", "Single step against two steps (the paper's figures 7 and 8)",
                                 main, notes));
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "paper_stats", "Traversal counters behind the paper table", stats,
                                 "Per primary+secondary ray of the last timed frame; `ns per ray` is "
                                 "wall time x threads / rays.\n"));
  PlotSpec ps;
  ps.title = "Two steps against single step";
  ps.x_label = "first-step levels";
  ps.y_label = "speed-up (single-step time / two-step time)";
  VOX_RETURN_IF_ERROR(WriteFile(ctx.out_dir + "/paper.svg", SvgPlot(ps, plot)));

  // The paper's findings, checked.
  std::string f = "## 1. The paper's table\n\n" + Provenance(ctx) + "\n" + main.Markdown() + "\n" + notes +
                  "\n![speed-up against first-step levels](paper.svg)\n\nFindings:\n\n";
  const Finding* big = nullptr;
  for (const auto& x : findings)
    if (x.grid == 2048 && x.image == 1024) big = &x;
  if (big)
    f += Fmt("- *Two steps up to 5x faster at 2048^3 and 1024^2*: measured %.2fx for the frame (best split "
             "%d+), %.2fx at 6+, %.2fx for first hits only. DDA moves per ray fall from %.0f to %.0f "
             "(%.1fx), but a frame costs %.0f ns per ray single step against %.0f two steps: the part of "
             "a ray's cost that is not DDA moves (set-up, octree descent, brick lookup, shading) does "
             "not shrink.\n",
             big->best_speedup, big->best_n1, big->speedup6, big->trav_speedup, big->moves_single,
             big->moves_best, big->moves_single / big->moves_best, big->ns_single, big->ns_best);
  int six = 0;
  std::string bests;
  for (const auto& x : findings) {
    six += x.best_n1 == 6;
    bests += Fmt("%s%d^3/%d^2: %d+", bests.empty() ? "" : ", ", x.grid, x.image, x.best_n1);
  }
  f += Fmt("- *Best split at 6 first-step levels*: %d of %zu configurations are fastest at 6+ (%s).\n", six,
           findings.size(), bests.c_str());
  for (int grid : grids) {
    const Finding *lo = nullptr, *hi = nullptr;
    for (const auto& x : findings)
      if (x.grid == grid) {
        if (!lo || x.image < lo->image) lo = &x;
        if (!hi || x.image > hi->image) hi = &x;
      }
    if (lo && hi && lo != hi)
      f += Fmt("- *Smaller gain at small images* (%d^3): %.2fx at %d^2 against %.2fx at %d^2.\n", grid,
               lo->best_speedup, lo->image, hi->best_speedup, hi->image);
  }
  *report += f + "\nCounters (moves, skips, transitions per ray): [paper_stats.md](paper_stats.md).\n\n";
  return OkStatus();
}

// ------------------------------------------------------------ 3. resolution

Status RunResolutionPart(const RunContext& ctx, std::string* report) {
  std::vector<int> res = ctx.quick ? std::vector<int>{128, 256, 512, 1024, 2048}
                                   : std::vector<int>{128, 256, 512, 1024, 2048, 4096};
  const int image = ctx.quick ? 512 : 1024;
  const Camera cam = StudyCamera(image, image);
  const Scene scene = DiffuseScene();
  struct Level {
    int across;
    std::string vdb, store;
    std::unique_ptr<Store> vol;
    std::unique_ptr<Renderer> r;
    std::vector<double> t;
    Image vox, vdb_mask;
    uint64_t bytes = 0;
  };
  std::vector<Level> L(res.size());
  for (size_t i = 0; i < res.size(); ++i) {
    L[i].across = res[i];
    VOX_ASSIGN_OR_RETURN(L[i].vdb, EnsureSphereVdb(ctx, res[i] * 15 / 16, 3.0));
    VOX_ASSIGN_OR_RETURN(L[i].store, EnsureStore(ctx, L[i].vdb));
    VOX_ASSIGN_OR_RETURN(L[i].vol, OpenStore(L[i].store));
    RenderOptions ro;
    VOX_ASSIGN_OR_RETURN(L[i].r, Renderer::Create(L[i].vol.get(), cam, scene, ro));
    L[i].bytes = DirectoryBytes(L[i].store);
    VOX_ASSIGN_OR_RETURN(L[i].vox, RenderImage(*L[i].r));
    std::string ppm = ctx.work_dir + Fmt("/res_vdb_%d_%d.ppm", res[i], image);
    VOX_RETURN_IF_ERROR(RunCommand("vdb_render " + Quote(L[i].vdb) + " " + Quote(ppm) + " " +
                                   VdbCameraArgs(image, image) + " -shader matte -cpus " +
                                   std::to_string(ctx.threads))
                            .status());
    VOX_ASSIGN_OR_RETURN(L[i].vdb_mask, ReadPpm(ppm));
    fprintf(stderr, "resolution: %d across ready\n", res[i]);
  }
  for (int round = 0; round < ctx.rounds; ++round)
    for (size_t k = 0; k < L.size(); ++k) {
      Level& l = L[(k + size_t(round)) % L.size()];
      VOX_ASSIGN_OR_RETURN(FrameStats st, TimeFrame(*l.r, ctx.threads));
      l.t.push_back(st.render_seconds);
    }
  const Level& fine = L.back();
  Table table({"voxels across", "levels", "split", "occupied voxels", "store size (MB)", "render (s)",
               "time / finest", "IoU vs finest vox", "shading MAD vs finest", "IoU vs vdb_render (same VDB)",
               "IoU vs vdb_render (finest VDB)", "mask pixels differing from vdb_render (finest)"});
  Series time_err{"vox silhouette vs vdb_render of the finest VDB", {}, {}, true};
  for (auto& l : L) {
    std::vector<double> ratio;
    for (int i = 0; i < ctx.rounds; ++i) ratio.push_back(l.t[size_t(i)] / fine.t[size_t(i)]);
    double iou_fine_vdb = MaskIoU(l.vox, fine.vdb_mask);
    table.Add({std::to_string(l.across), std::to_string(l.vol->meta().levels), l.r->SplitString(),
               std::to_string(l.vol->meta().voxel_count), Fmt("%.2f", double(l.bytes) / 1e6),
               Secs(Median(l.t)), Fmt("%.3f", Median(ratio)), Fmt("%.5f", MaskIoU(l.vox, fine.vox)),
               Fmt("%.4f", MeanAbsShadingDiff(l.vox, fine.vox)), Fmt("%.5f", MaskIoU(l.vox, l.vdb_mask)),
               Fmt("%.5f", iou_fine_vdb), std::to_string(MaskDifferences(l.vox, fine.vdb_mask))});
    time_err.points.push_back({Median(l.t), std::max(1.0 - iou_fine_vdb, 1e-6)});
    time_err.labels.push_back(std::to_string(l.across));
  }
  VOX_RETURN_IF_ERROR(WriteMaskDiffPpm(ctx.work_dir + "/resolution_mask_diff.ppm", L.front().vox, fine.vdb_mask));
  std::string notes = Fmt(
      "Object: the level-set sphere (vdb_tool -sphere, radius 1) made with N*15/16 voxels across its "
      "diameter, ingested with `auto` levels, rendered at %dx%d from the study camera (0,0,3), "
      "40 degrees, with one directional light. IoU: silhouette masks (vox: alpha > 0.5; vdb_render "
      "-shader matte: luminance > 0.5, since its alpha is 1 everywhere). Shading MAD: mean absolute "
      "luminance difference over pixels both renders cover. vdb_render intersects the interpolated "
      "level set (sub-voxel); vox stops at the first occupied voxel (value <= 0), so a vox silhouette "
      "is up to a voxel wider.\n",
      image, image);
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "resolution", "Resolution against time", table, notes));
  PlotSpec ps;
  ps.title = "Resolution against time (labels: voxels across)";
  ps.x_label = "render time (s)";
  ps.y_label = "1 - silhouette IoU vs vdb_render (finest)";
  ps.log_x = ps.log_y = true;
  VOX_RETURN_IF_ERROR(WriteFile(ctx.out_dir + "/resolution.svg", SvgPlot(ps, {time_err})));
  *report += "## 3. Resolution against time\n\n" + Provenance(ctx) + "\n" + table.Markdown() + "\n" + notes +
             "\n![resolution against time](resolution.svg)\n\n";
  return OkStatus();
}

// ------------------------------------------------------------ 4. effects

Status RunEffectsPart(const RunContext& ctx, std::string* report) {
  const int image = ctx.quick ? 512 : 1024;
  VOX_ASSIGN_OR_RETURN(std::string vdb, EnsureSphereVdb(ctx, 1024 * 15 / 16, 3.0));
  VOX_ASSIGN_OR_RETURN(std::string store, EnsureStore(ctx, vdb));
  VOX_ASSIGN_OR_RETURN(auto vol, OpenStore(store));
  const Camera cam = StudyCamera(image, image);
  const std::string light = R"({"type":"directional","direction":[-0.3,-0.5,-1],"shadows":false})";
  const std::string light_sh = R"({"type":"directional","direction":[-0.3,-0.5,-1],"shadows":true})";
  struct Row {
    std::string name, json;
  };
  const std::vector<Row> rows = {
      {"visibility (no light: ambient only)", R"({"lights":[],"ambient":[1,1,1],"max_depth":0})"},
      {"+ shading (one light)", R"({"lights":[)" + light + R"(],"max_depth":0})"},
      {"+ shadows", R"({"lights":[)" + light_sh + R"(],"max_depth":0})"},
      {"+ reflection (reflect 0.3)", R"({"lights":[)" + light_sh + R"(],"max_depth":4,"material":{"reflect":0.3}})"},
      {"+ refraction (transmit 0.3)",
       R"({"lights":[)" + light_sh + R"(],"max_depth":4,"material":{"reflect":0.3,"transmit":0.3}})"},
      {"control: shading again", R"({"lights":[)" + light + R"(],"max_depth":0})"},
      {"control: shading, max_depth 8, reflect = transmit = 0", R"({"lights":[)" + light + R"(],"max_depth":8})"},
      {"control: shading + a shadow-casting light of intensity 0",
       R"({"lights":[)" + light +
           R"(,{"type":"directional","direction":[0.5,-0.5,-1],"intensity":0,"shadows":true}],"max_depth":0})"},
  };
  std::vector<std::unique_ptr<Renderer>> rs;
  for (const Row& row : rows) {
    VOX_ASSIGN_OR_RETURN(Scene s, ParseScene(row.json, row.name));
    VOX_ASSIGN_OR_RETURN(auto r, Renderer::Create(vol.get(), cam, s, RenderOptions{}));
    VOX_RETURN_IF_ERROR(TimeFrame(*r, ctx.threads).status());  // warm-up
    rs.push_back(std::move(r));
  }
  std::vector<std::vector<double>> t(rows.size());
  std::vector<FrameStats> last(rows.size());
  for (int round = 0; round < ctx.rounds; ++round)
    for (size_t k = 0; k < rows.size(); ++k) {
      size_t c = (k + size_t(round)) % rows.size();
      VOX_ASSIGN_OR_RETURN(FrameStats st, TimeFrame(*rs[c], ctx.threads));
      t[c].push_back(st.render_seconds);
      last[c] = st;
    }
  Table table({"scene", "passes", "render (s)", "time / shading", "primary rays", "shadow rays",
               "reflection rays", "refraction rays", "DDA moves / pixel", "scene.json"});
  for (size_t c = 0; c < rows.size(); ++c) {
    std::vector<double> ratio;
    for (int i = 0; i < ctx.rounds; ++i) ratio.push_back(t[c][size_t(i)] / t[1][size_t(i)]);
    const RenderCounters& rc = last[c].counters;
    table.Add({rows[c].name, rs[c]->passes().ToString(), Secs(Median(t[c])), Fmt("%.3f", Median(ratio)),
               std::to_string(rc.rays[kRayPrimary]), std::to_string(rc.rays[kRayShadow]),
               std::to_string(rc.rays[kRayReflection]), std::to_string(rc.rays[kRayRefraction]),
               Fmt("%.1f", PerRay(rc.trace.total_moves(), rc.pixels)), "`" + rows[c].json + "`"});
  }
  std::string notes = Fmt(
      "Store: the level-set sphere 960 voxels across (1024^3 grid, default split), %dx%d, study "
      "camera. `time / shading`: median over rounds of this scene's time / the `+ shading` time of "
      "the same round. The controls show what an effect the scene does not call for costs: zero rays "
      "of its kind, and a time ratio as close to 1 as `control: shading again` (the same scene timed "
      "twice, i.e. the noise).\n",
      image, image);
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "effects", "Effects against time", table, notes));
  *report += "## 4. Effects against time\n\n" + Provenance(ctx) + "\n" + table.Markdown() + "\n" + notes + "\n";
  return OkStatus();
}

// ------------------------------------------------------------ 5. peer

Status RunPeerPart(const RunContext& ctx, std::string* report) {
  const int image = ctx.quick ? 512 : 1024;
  struct Case {
    std::string name, vdb, store;
    std::unique_ptr<Store> vol;
    std::unique_ptr<Renderer> r;
    std::vector<double> vox_t, vdb_t;
    double iou = 0;
    uint64_t differ = 0;
  };
  std::vector<Case> cases;
  for (int across : {1024, 2048}) {
    Case c;
    c.name = Fmt("sphere %d^3", across);
    VOX_ASSIGN_OR_RETURN(c.vdb, EnsureSphereVdb(ctx, across * 15 / 16, 3.0));
    cases.push_back(std::move(c));
  }
  {
    Case c;
    c.name = "icosahedron 1024";
    VOX_ASSIGN_OR_RETURN(c.vdb, EnsurePlatonicVdb(ctx, 20, 1024));
    cases.push_back(std::move(c));
  }
  const Camera cam = StudyCamera(image, image);
  for (Case& c : cases) {
    VOX_ASSIGN_OR_RETURN(c.store, EnsureStore(ctx, c.vdb));
    VOX_ASSIGN_OR_RETURN(c.vol, OpenStore(c.store));
    VOX_ASSIGN_OR_RETURN(c.r, Renderer::Create(c.vol.get(), cam, DiffuseScene(), RenderOptions{}));
    VOX_ASSIGN_OR_RETURN(Image vox, RenderImage(*c.r));
    std::string ppm = ctx.work_dir + "/peer_matte.ppm";
    VOX_RETURN_IF_ERROR(RunCommand("vdb_render " + Quote(c.vdb) + " " + Quote(ppm) + " " +
                                   VdbCameraArgs(image, image) + " -shader matte -cpus " +
                                   std::to_string(ctx.threads))
                            .status());
    VOX_ASSIGN_OR_RETURN(Image vdbm, ReadPpm(ppm));
    c.iou = MaskIoU(vox, vdbm);
    c.differ = MaskDifferences(vox, vdbm);
    VOX_RETURN_IF_ERROR(TimeFrame(*c.r, ctx.threads).status());  // warm-up
  }
  for (int round = 0; round < ctx.rounds; ++round)
    for (Case& c : cases) {
      VOX_ASSIGN_OR_RETURN(FrameStats st, TimeFrame(*c.r, ctx.threads));
      c.vox_t.push_back(st.render_seconds);
      VOX_ASSIGN_OR_RETURN(std::string out,
                           RunCommand("vdb_render " + Quote(c.vdb) + " " + Quote(ctx.work_dir + "/peer.ppm") +
                                      " " + VdbCameraArgs(image, image) + " -shader diffuse -v -cpus " +
                                      std::to_string(ctx.threads)));
      VOX_ASSIGN_OR_RETURN(double s, VdbRayTracingSeconds(out));
      c.vdb_t.push_back(s);
    }
  Table table({"scene", "occupied voxels", "split", "vox render (s)", "vdb_render ray-tracing (s)",
               "vdb_render / vox", "silhouette IoU", "mask pixels differing"});
  for (Case& c : cases) {
    std::vector<double> ratio;
    for (int i = 0; i < ctx.rounds; ++i) ratio.push_back(c.vdb_t[size_t(i)] / c.vox_t[size_t(i)]);
    table.Add({c.name, std::to_string(c.vol->meta().voxel_count), c.r->SplitString(), Secs(Median(c.vox_t)),
               Secs(Median(c.vdb_t)), Ratio(Median(ratio)), Fmt("%.5f", c.iou), std::to_string(c.differ)});
  }
  std::string notes = Fmt(
      "%dx%d, %d threads each, same camera (vox cam.json = vdb_render %s). vox: whole frame in "
      "process, warm cache, no EXR write, one directional light without shadows; vdb_render: its own "
      "`-v` ray-tracing time with `-shader diffuse` (file load and write excluded). Each round runs "
      "vox then vdb_render on each scene; the ratio is the median of per-round ratios. Masks: vox "
      "alpha against vdb_render `-shader matte` luminance.\n",
      image, image, ctx.threads, VdbCameraArgs(image, image).c_str());
  VOX_RETURN_IF_ERROR(WriteTable(ctx, "peer", "vox against vdb_render", table, notes));
  *report += "## 5. Peer: vdb_render\n\n" + Provenance(ctx) + "\n" + table.Markdown() + "\n" + notes + "\n";
  return OkStatus();
}

}  // namespace vox::bench

namespace {

std::string MachineString() {
  std::string cpu = "unknown CPU";
  std::ifstream f("/proc/cpuinfo");
  for (std::string line; std::getline(f, line);)
    if (line.rfind("model name", 0) == 0) {
      size_t p = line.find(':');
      cpu = line.substr(p + 2);
      break;
    }
  long n = sysconf(_SC_NPROCESSORS_ONLN);
  return std::to_string(n) + " cores (nproc), " + cpu;
}

std::string UtcNow() {
  time_t t = time(nullptr);
  char buf[64];
  strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", gmtime(&t));
  return buf;
}

// "1024,2048" -> {1024, 2048}; false on anything but powers of two in [min, max].
bool ParseSizes(const std::string& text, int min, int max, std::vector<int>* out) {
  out->clear();
  for (std::stringstream ss(text); ss.good();) {
    std::string t;
    std::getline(ss, t, ',');
    char* end = nullptr;
    long v = std::strtol(t.c_str(), &end, 10);
    if (t.empty() || *end != '\0' || v < min || v > max || (v & (v - 1)) != 0) return false;
    out->push_back(int(v));
  }
  return !out->empty();
}

int Usage() {
  fprintf(stderr,
          "usage: vox-bench [--quick] [--out DIR] [--work DIR] [--threads N] [--rounds N]\n"
          "                 [--parts paper,precision,resolution,effects,peer]\n"
          "                 [--grids 1024,2048] [--images 256,512,1024]\n"
          "  --quick    small configuration (a few minutes on 2 cores)\n"
          "  --out      where tables, CSV and SVG go (default docs/bench-quick or docs/bench-full)\n"
          "  --work     cached volumes and stores (default /tmp/vox-bench)\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace vox::bench;
  RunContext ctx;
  ctx.quick = false;
  ctx.work_dir = "/tmp/vox-bench";
  std::string out, parts = "paper,precision,resolution,effects,peer";
  int rounds = 0;
  std::string cmd = "vox-bench";
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    cmd += " " + a;
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        fprintf(stderr, "vox-bench: %s needs a value\n", a.c_str());
        exit(2);
      }
      cmd += std::string(" ") + argv[i + 1];
      return argv[++i];
    };
    if (a == "--quick") ctx.quick = true;
    else if (a == "--out") out = next();
    else if (a == "--work") ctx.work_dir = next();
    else if (a == "--threads") ctx.threads = std::atoi(next());
    else if (a == "--rounds") rounds = std::atoi(next());
    else if (a == "--parts") parts = next();
    else if (a == "--grids") {
      if (!ParseSizes(next(), 64, 1 << 20, &ctx.grids)) {
        fprintf(stderr, "vox-bench: --grids wants powers of two from 64 to 2^20, e.g. 1024,2048\n");
        return 2;
      }
    } else if (a == "--images") {
      if (!ParseSizes(next(), 16, 16384, &ctx.images)) {
        fprintf(stderr, "vox-bench: --images wants powers of two from 16 to 16384, e.g. 256,512\n");
        return 2;
      }
    }
    else if (a == "--help" || a == "-h") return Usage();
    else {
      fprintf(stderr, "vox-bench: unknown argument '%s'\n", a.c_str());
      return Usage();
    }
  }
  if (ctx.threads < 1 || ctx.threads > 1024) {
    fprintf(stderr, "vox-bench: --threads must be 1..1024\n");
    return 2;
  }
  std::set<std::string> known = {"paper", "precision", "resolution", "effects", "peer"}, want;
  for (std::stringstream ss(parts); ss.good();) {
    std::string p;
    std::getline(ss, p, ',');
    if (p.empty()) continue;
    if (!known.count(p)) {
      fprintf(stderr, "vox-bench: unknown part '%s' (parts: paper,precision,resolution,effects,peer)\n", p.c_str());
      return 2;
    }
    want.insert(p);
  }
  ctx.rounds = rounds > 0 ? rounds : (ctx.quick ? 3 : 5);
  ctx.out_dir = out.empty() ? (ctx.quick ? "docs/bench-quick" : "docs/bench-full") : out;
  ctx.command = cmd;
  ctx.machine = MachineString();
  ctx.date = UtcNow();
  std::error_code ec;
  std::filesystem::create_directories(ctx.out_dir, ec);
  if (ec) {
    fprintf(stderr, "vox-bench: cannot create %s: %s\n", ctx.out_dir.c_str(), ec.message().c_str());
    return 1;
  }
  std::filesystem::create_directories(ctx.work_dir, ec);
  if (ec) {
    fprintf(stderr, "vox-bench: cannot create %s: %s\n", ctx.work_dir.c_str(), ec.message().c_str());
    return 1;
  }
  // index.md: every part's section (section_NAME.md, rewritten when the part
  // runs, kept otherwise), so `--parts` can redo one part.
  int failures = 0;
  const char* order[] = {"paper", "precision", "resolution", "effects", "peer"};
  auto write_index = [&]() {
    std::string index = "# vox-bench results\n\nEach section says the command that produced it. Sections "
                        "are also in their own files (paper.md, precision.md, resolution.md, effects.md, "
                        "peer.md) with CSV.\n\n";
    for (const char* name : order) {
      std::ifstream f(ctx.out_dir + "/section_" + name + ".md");
      if (f) index += std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    }
    return WriteFile(ctx.out_dir + "/index.md", index);
  };
  auto run = [&](const char* name, vox::Status (*fn)(const RunContext&, std::string*)) {
    if (!want.count(name)) return;
    fprintf(stderr, "vox-bench: %s ...\n", name);
    std::string report;
    vox::Status s = fn(ctx, &report);
    if (!s.ok()) {
      ++failures;
      fprintf(stderr, "vox-bench: %s failed: %s\n", name, s.ToString().c_str());
      report += std::string("**") + name + " failed** (`" + ctx.command + "`): " + s.ToString() + "\n\n";
    }
    (void)WriteFile(ctx.out_dir + "/section_" + name + ".md", report);
    (void)write_index();
  };
  run("paper", RunPaperPart);
  run("precision", RunPrecisionPart);
  run("resolution", RunResolutionPart);
  run("effects", RunEffectsPart);
  run("peer", RunPeerPart);
  vox::Status s = write_index();
  if (!s.ok()) {
    fprintf(stderr, "vox-bench: %s\n", s.ToString().c_str());
    return 1;
  }
  fprintf(stderr, "vox-bench: wrote %s/index.md%s\n", ctx.out_dir.c_str(),
          failures ? " (some parts failed)" : "");
  return failures ? 1 : 0;
}

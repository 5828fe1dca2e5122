// vox-render-bench: times vox's renderer on a store in one process: the first
// frame with an empty brick cache (cold), then warm frames; prints JSON with
// the times, their median, rays/s and DDA moves/s. tools/bench/render_bench.sh
// runs it side by side with vdb_render.
//   vox-render-bench STORE --cam cam.json [--scene s.json] [--runs N]
//                    [--threads N] [--split N1+N2|N1] [--exr out.exr] [--cache-mb M]
//                    [--tile-size T] [--bare] [--mask out.pgm]
// --bare: the bare loop (RenderOptions::first_hits_only): the same ray
// generation and tile loop as vox-render, each primary ray's first hit
// only, no shading; the comparison with a peer's first-hit loop (NanoVDB's
// HDDA + ZeroCrossing). --mask writes the last frame's hit mask (alpha > 0)
// as a binary PGM, row 0 on top.
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/tracer.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/session.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "storage/store.h"
#include "tools/common/flags.h"

int main(int argc, char** argv) {
  std::string store, cam_path, scene_path, split, exr, mask_path;
  bool bare = false;
  std::optional<double> lod;  // unset: vox-render's default (OpenRenderStores)
  int runs = 5, threads = 2, tile_size = 64;
  size_t cache_mb = 2048;
  vox::FlagReader flags(argc, argv);
  auto usage = [] {
    fprintf(stderr,
            "usage: vox-render-bench STORE --cam cam.json [--scene s.json] [--runs N] "
            "[--threads N] [--split S] [--exr out.exr] [--cache-mb M] [--tile-size T] [--lod F]\n"
            "       [--bare] [--mask out.pgm]\n"
            "  --lod F: as vox-render's (default: 1 when the store has a pyramid, else 0;\n"
            "           --lod 0 is the exact frame, for comparisons with peers)\n");
    return 2;
  };
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (!flags.IsFlag()) {
      if (!store.empty()) return usage();
      store = a;
      continue;
    }
    if (a == "--bare") {
      bare = true;
      continue;
    }
    if (a != "--mask" && a != "--cam" && a != "--scene" && a != "--split" && a != "--exr" &&
        a != "--runs" && a != "--threads" && a != "--tile-size" && a != "--cache-mb" &&
        a != "--lod")
      return usage();
    const std::optional<std::string> v = flags.Value();
    if (!v) {
      fprintf(stderr, "vox-render-bench: %s needs a value\n", a.c_str());
      return 2;
    }
    bool ok = true;
    int64_t mb = 0;
    if (a == "--mask")
      mask_path = *v;
    else if (a == "--cam")
      cam_path = *v;
    else if (a == "--scene")
      scene_path = *v;
    else if (a == "--split")
      split = *v;
    else if (a == "--exr")
      exr = *v;
    else if (a == "--lod") {
      auto f = vox::ParseLodFactor("--lod", *v);
      if (!f.ok()) {
        fprintf(stderr, "vox-render-bench: %s\n", f.status().ToString().c_str());
        return 2;
      }
      lod = *f;
    }
    else if (a == "--runs")
      ok = vox::ParseInt(*v, -1000000, 1000000, &runs);
    else if (a == "--threads")
      ok = vox::ParseInt(*v, -1000000, 1000000, &threads);
    else if (a == "--tile-size")
      ok = vox::ParseInt(*v, -1000000, 1000000, &tile_size);
    else if ((ok = vox::ParseInt(*v, 0, INT64_MAX >> 20, &mb)))
      cache_mb = size_t(mb);
    if (!ok) {
      fprintf(stderr, "vox-render-bench: %s '%s': not a number\n", a.c_str(), v->c_str());
      return 2;
    }
  }
  runs = std::max(2, runs);
  tile_size = std::max(1, tile_size);
  if (store.empty() || cam_path.empty()) {
    fprintf(stderr, "vox-render-bench: need STORE and --cam\n");
    return 2;
  }
  auto fail = [](const vox::Status& s) {
    fprintf(stderr, "vox-render-bench: %s\n", s.ToString().c_str());
    return 1;
  };
  vox::OpenOptions oo;
  oo.cache_bytes = cache_mb << 20;
  auto stores = vox::OpenRenderStores(store, lod, oo);
  if (!stores.ok()) return fail(stores.status());
  vox::Store* vol = stores->base.get();
  auto cam = vox::LoadCamera(cam_path);
  if (!cam.ok()) return fail(cam.status());
  vox::Scene scene;
  if (!scene_path.empty()) {
    auto s = vox::LoadScene(scene_path);
    if (!s.ok()) return fail(s.status());
    scene = *s;
  }
  vox::RenderOptions ro;
  ro.lod = stores->lod;
  ro.first_hits_only = bare;
  for (vox::Store* level : stores->levels) ro.lod_levels.push_back(level);
  if (!split.empty()) {
    auto n1 = vox::ParseSplit(split, vol->meta().levels);
    if (!n1.ok()) return fail(n1.status());
    ro.n1 = *n1;
  }
  auto renderer = vox::Renderer::Create(vol, *cam, scene, ro);
  if (!renderer.ok()) return fail(renderer.status());
  auto cpu_now = [] {
    rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
           1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  };
  std::vector<double> secs, cpu;
  vox::FrameStats last;
  std::vector<uint8_t> mask;
  if (!mask_path.empty()) mask.assign(size_t(cam->width) * size_t(cam->height), 0);
  for (int r = 0; r < runs; ++r) {
    vox::FrameOptions fo;
    fo.exr_path = exr;
    fo.threads = threads;
    fo.tile_size = tile_size;
    if (!mask.empty() && r + 1 == runs)
      fo.on_tile = [&](const vox::TileRect& t, const vox::TileBuffer& b) {
        for (int y = 0; y < t.h; ++y)
          for (int x = 0; x < t.w; ++x)
            mask[size_t(t.y0 + y) * size_t(cam->width) + size_t(t.x0 + x)] =
                b.ch[vox::kChA][size_t(y) * size_t(b.size) + size_t(x)] > 0 ? 255 : 0;
        return vox::OkStatus();
      };
    vox::FrameStats st;
    const double c0 = cpu_now();
    vox::Status s = vox::RenderFrame(**renderer, fo, &st);
    if (!s.ok()) return fail(s);
    secs.push_back(st.render_seconds);
    cpu.push_back(cpu_now() - c0);
    last = st;
  }
  if (!mask.empty()) {
    FILE* m = fopen(mask_path.c_str(), "wb");
    if (m == nullptr || fprintf(m, "P5\n%d %d\n255\n", cam->width, cam->height) < 0 ||
        fwrite(mask.data(), 1, mask.size(), m) != mask.size() || fclose(m) != 0) {
      fprintf(stderr, "vox-render-bench: cannot write %s\n", mask_path.c_str());
      return 1;
    }
  }
  std::vector<double> warm(secs.begin() + 1, secs.end());
  std::sort(warm.begin(), warm.end());
  double median = warm.size() % 2 ? warm[warm.size() / 2]
                                  : 0.5 * (warm[warm.size() / 2 - 1] + warm[warm.size() / 2]);
  auto median_of = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  };
  const double cpu_median = median_of(std::vector<double>(cpu.begin() + 1, cpu.end()));
  uint64_t rays = 0;
  for (int k = 0; k < vox::kNumRayKinds; ++k) rays += last.counters.rays[k];
  nlohmann::json j;
  j["store"] = store;
  j["width"] = cam->width;
  j["height"] = cam->height;
  j["threads"] = threads;
  j["tile_size"] = tile_size;
  j["split"] = (*renderer)->SplitString();
  j["passes"] = (*renderer)->passes().ToString();
  j["lod"] = stores->lod;
  j["lod_default"] = stores->lod_default;
  j["write_exr"] = !exr.empty();
  j["bare"] = bare;
  j["hits"] = last.counters.hit_pixels;
  j["warm_best_seconds"] = warm.front();
  j["cold_seconds"] = secs[0];
  j["warm_seconds"] = warm;
  j["warm_median_seconds"] = median;
  j["cold_cpu_seconds"] = cpu[0];
  j["warm_cpu_median_seconds"] = cpu_median;
  j["rays"] = rays;
  j["dda_moves"] = last.counters.trace.total_moves();
  j["warm_rays_per_second"] = double(rays) / median;
  j["warm_dda_moves_per_second"] = double(last.counters.trace.total_moves()) / median;
  printf("%s\n", j.dump(2).c_str());
  return 0;
}

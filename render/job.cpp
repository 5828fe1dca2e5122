#include "render/job.h"

#include <algorithm>
#include <cmath>
#include <charconv>
#include <malloc.h>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/stopwatch.h"
#include "core/tracer.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/grid_transform.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "storage/atomic_file.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_budget.h"

namespace vox {
namespace {

// --stats "lod": the factor, stops by level, and per level the bricks paged
// in and bytes read (level 0: the base store, as in "cache" and "io").
nlohmann::json LodStatsJson(const Renderer& r, const FrameStats& st,
                            const std::vector<Store*>& levels,
                            const std::vector<CacheStats>& start) {
  nlohmann::json j;
  j["factor"] = r.lod()->factor();
  j["levels"] = r.lod()->max_level();
  j["exact_rays"] = st.counters.lod.exact_rays;
  nlohmann::json stops = nlohmann::json::object(), paged = nlohmann::json::array(),
                 bytes = nlohmann::json::array();
  for (int l = 0; l <= kMaxLevels; ++l)
    if (st.counters.lod.stops[l] > 0) stops[std::to_string(l)] = st.counters.lod.stops[l];
  uint64_t total_paged = st.cache_end.misses - st.cache_start.misses;
  uint64_t total_bytes = st.cache_end.bytes_read - st.cache_start.bytes_read;
  paged.push_back(total_paged);
  bytes.push_back(total_bytes);
  for (size_t i = 0; i < levels.size(); ++i) {
    const CacheStats e = levels[i]->cache_stats();
    paged.push_back(e.misses - start[i].misses);
    bytes.push_back(e.bytes_read - start[i].bytes_read);
    total_paged += e.misses - start[i].misses;
    total_bytes += e.bytes_read - start[i].bytes_read;
  }
  j["stops_by_level"] = stops;
  j["bricks_paged_by_level"] = paged;
  j["brick_bytes_read_by_level"] = bytes;
  j["bricks_paged_total"] = total_paged;
  j["brick_bytes_read_total"] = total_bytes;
  return j;
}

// Without --lod: when the voxels where the volume begins are much smaller
// than a pixel of the central ray, says once that --lod 1 would read about
// N times fewer bricks (N from the pyramid's brick counts at the level the
// central pixel's cone picks there).
void LodHint(const std::string& dir, Store& base, const Camera& cam, FILE* log) {
  const StoreMeta& m = base.meta();
  if (m.voxel_count == 0 || !(m.voxel_size > 0)) return;
  glm::dvec3 lo, hi;
  WorldBounds(m, &lo, &hi);
  // The central pixel's width where the volume begins (the nearest point of
  // its box: most of what a full view sees lies about that far).
  const glm::dvec3 nearest = glm::clamp(cam.position, lo, hi);
  double pixel;
  if (cam.projection == Projection::kPerspective)
    pixel = glm::length(nearest - cam.position) * 2.0 *
            std::tan(cam.fov_deg * (3.14159265358979323846 / 360.0)) / cam.width;
  else
    pixel = cam.ortho_width / cam.width;
  const double voxels = pixel / m.voxel_size;
  if (!(voxels >= 4.0)) return;  // "much smaller": at least level 2
  const int want = std::min(std::ilogb(voxels), LodMaxLevel(m.levels));
  if (want < 1) return;
  std::string estimate = "fewer";
  if (HasLod(dir)) {
    OpenOptions oo;
    oo.cache_bytes = 4 << 20;
    auto p = LodPyramid::Open(dir, base, oo);
    if (p.ok() && (*p)->max_level() >= want) {
      const std::vector<uint64_t> n = (*p)->brick_counts();
      if (n[size_t(want)] > 0) {
        char b[64];
        snprintf(b, sizeof b, "about %.0fx fewer", double(n[0]) / double(n[size_t(want)]));
        estimate = b;
      }
    }
  }
  fprintf(log,
          "vox-render: about %.1f voxels fall across a pixel at the volume's front; --lod 1 would "
          "read %s bricks%s\n",
          voxels, estimate.c_str(),
          HasLod(dir) ? "" : (" (add the pyramid first: vox-ingest --add-lod " + dir + ")").c_str());
}

}  // namespace

Status RunRenderJob(const RenderJobOptions& o, RenderJobOutput* out) {
  const Stopwatch total;
  Stopwatch phase;
  if (!o.preview_path.empty() && o.exr_path.empty())
    return InvalidArgumentError("--preview needs an EXR output (-o)");
  if (!o.preview_path.empty() && !o.part.whole())
    return InvalidArgumentError(
        "--preview needs the whole image; with --tiles, preview the vox-merge output");
  // Output paths are checked before any work: a bad one fails in a moment,
  // not after the render. The files are written atomically at the end.
  for (const std::string* out : {&o.exr_path, &o.preview_path, &o.stats_path})
    if (!out->empty()) VOX_RETURN_IF_ERROR(CheckOutputPath(*out));
  if (o.threads < 0)
    return InvalidArgumentError("threads " + std::to_string(o.threads) +
                                ": must not be negative (0: all cores)");
  VOX_ASSIGN_OR_RETURN(const ProcessBudget process, ChooseProcessBudget(o.memory_bytes));
  OpenOptions open;
  // The budget bounds the cache (BudgetStore sets it once the resident top
  // is known); opening with it gives the cache its number of shards.
  open.cache_bytes = o.cache_mb > 0 ? o.cache_mb << 20 : process.bytes;
  if (o.io_threads < 1 || o.io_threads > kMaxIoThreads)
    return InvalidArgumentError("--io-threads " + std::to_string(o.io_threads) + ": must be 1.." +
                                std::to_string(kMaxIoThreads));
  // Each I/O thread holds a run of bricks in its buffer and in the page
  // cache (2 x kPrefetchRunBytes): at most one per 32 MiB of budget, so a
  // small budget keeps its memory for the cache.
  const int io_threads = o.prefetch ? int(std::clamp<uint64_t>(process.bytes / (32 * kMiB), 1,
                                                               uint64_t(o.io_threads)))
                                    : 0;
  open.io_threads = std::max(io_threads, 1);
  open.read_windows = o.read_windows;
  if (o.lod != 0.0 && !(o.lod > 0 && std::isfinite(o.lod)))
    return InvalidArgumentError("--lod " + std::to_string(o.lod) + ": must be finite and > 0");
  VOX_ASSIGN_OR_RETURN(auto volume, Store::Open(o.store_dir, open));
  std::unique_ptr<LodPyramid> pyramid;
  std::vector<Store*> lod_stores;
  if (o.lod > 0) {
    OpenOptions lo = open;
    auto p = LodPyramid::Open(o.store_dir, *volume, lo);
    if (!p.ok()) return p.status().WithContext("--lod");
    pyramid = std::move(p).value();
    for (int l = 1; l <= pyramid->max_level(); ++l) lod_stores.push_back(pyramid->level(l));
  }
  // Open's scratch (the index blocks, as large as the resident top) is
  // free but stays in the main heap, which the render threads' allocator
  // arenas do not reuse: give it back so the budget's estimate holds.
  malloc_trim(0);
  const double open_seconds = phase.Lap();
  const StoreMeta& meta = volume->meta();

  Camera camera;
  if (o.camera_path.empty() && !o.camera_json.empty()) {
    VOX_ASSIGN_OR_RETURN(camera, ParseCamera(o.camera_json, "camera"));
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    VOX_RETURN_IF_ERROR(CheckCameraDistance(camera, lo, hi).WithContext("camera"));
  } else if (o.camera_path.empty()) {
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    camera = DefaultCamera(lo, hi, o.default_width, o.default_height);
  } else {
    VOX_ASSIGN_OR_RETURN(camera, LoadCamera(o.camera_path));
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    VOX_RETURN_IF_ERROR(CheckCameraDistance(camera, lo, hi).WithContext(o.camera_path));
  }
  Scene scene;
  if (!o.scene_path.empty()) {
    VOX_ASSIGN_OR_RETURN(scene, LoadScene(o.scene_path));
  } else if (!o.scene_json.empty()) {
    VOX_ASSIGN_OR_RETURN(scene, ParseScene(o.scene_json, "scene"));
  }

  RenderOptions ro;
  ro.layers = o.layers;
  ro.beam = o.beam;
  if (o.single_step && !o.split.empty())
    return InvalidArgumentError("--split and --single-step both choose the split; give one");
  if (o.single_step) {
    ro.n1 = meta.levels;
  } else if (!o.split.empty()) {
    VOX_ASSIGN_OR_RETURN(ro.n1, ParseSplit(o.split, meta.levels));
  }
  // The budget's split, before any output exists: a store whose resident
  // top does not fit fails here, saying how much it needs.
  const int threads =
      o.threads > 0 ? o.threads : int(std::max(1u, std::thread::hardware_concurrency()));
  BudgetInputs bi;
  bi.image_width = camera.width;
  bi.image_height = camera.height;
  bi.tile_size = std::clamp(o.tile_size, kMinTileSize, kMaxTileSize);
  bi.threads = threads;
  bi.channels = 5 + (o.layers.normal ? 3 : 0) + (o.layers.voxel ? 3 : 0);
  bi.cache_override = uint64_t(o.cache_mb) << 20;
  bi.io_threads = io_threads;
  bi.read_window_bytes = o.read_windows ? kMaxReadWindowBytes : 0;
  const bool keep = o.keep_image && out != nullptr;
  const size_t pixels = size_t(camera.width) * size_t(camera.height);
  if (keep) bi.process_base += uint64_t(pixels) * uint64_t(bi.channels) * sizeof(float);
  // --lod: the levels finer than any ray of this camera can stop at get no
  // more than the minimum cache (a full view of a huge volume uses none of
  // the base's bricks), unless the scene refracts (refraction is exact).
  int first_level = 0;
  if (o.lod > 0 && !SceneRefracts(scene)) {  // refracted rays are traced exactly
    std::vector<Volume*> levels(lod_stores.begin(), lod_stores.end());
    VOX_ASSIGN_OR_RETURN(const LodTracer lt, LodTracer::Create(volume.get(), levels, o.lod));
    glm::dvec3 lo, hi;
    WorldBounds(meta, &lo, &hi);
    first_level = lt.FirstLevelSeen(camera, PrimaryConeOf(camera, meta.voxel_size), lo, hi);
  }
  VOX_ASSIGN_OR_RETURN(const MemoryBudget budget,
                       BudgetStores(volume.get(), lod_stores, process.bytes, bi, first_level));
  int slot_bits = 0;
  while ((2 << slot_bits) <= budget.pins_per_thread) ++slot_bits;
  ro.table_slot_bits = slot_bits;
  if (!o.quiet)
    fprintf(o.log, "vox-render: memory %s; %s\n", process.ToString().c_str(),
            budget.ToString().c_str());
  if (o.prefetch) {
    Store* store = volume.get();
    ro.read_ahead = [store](std::span<const uint32_t> ids) { store->Prefetch(ids); };
  }
  ro.lod = o.lod;
  for (Store* s : lod_stores) ro.lod_levels.push_back(s);
  VOX_ASSIGN_OR_RETURN(auto renderer, Renderer::Create(volume.get(), camera, scene, ro));
  if (o.lod == 0.0 && !o.quiet) LodHint(o.store_dir, *volume, camera, o.log);
  const double setup_seconds = phase.Lap();
  std::vector<CacheStats> lod_start;
  for (Store* s : lod_stores) lod_start.push_back(s->cache_stats());

  FrameOptions fo;
  fo.exr_path = o.exr_path;
  fo.threads = threads;
  if (o.prefetch) {
    Store* store = volume.get();
    fo.prefetch = [store](std::span<const uint32_t> ids) { store->Prefetch(ids); };
    fo.prefetch_backlog = [store] { return store->PrefetchBacklog(); };
    // Half the cache may hold bricks read ahead (Store::Prefetch); the scout
    // waits at a quarter so the store seldom has to drop requests.
    fo.prefetch_limit = budget.brick_cache / 4;
  }
  fo.tile_size = o.tile_size;
  fo.part = o.part;
  fo.compression = o.compression;
  fo.progress = ChooseProgressMode(o.log, o.quiet);
  fo.progress_out = o.log;
  fo.attrs["vox:store"] = o.store_dir;
  {
    char id[17];
    snprintf(id, sizeof id, "%016llx", (unsigned long long)volume->store_id());
    fo.attrs["vox:storeId"] = id;  // vox-merge refuses parts of different stores
  }
  fo.attrs["vox:grid"] = meta.grid_name;
  fo.attrs["vox:source"] = meta.source_file;
  if (keep) {
    out->width = camera.width;
    out->height = camera.height;
    out->rgba.assign(pixels * 4, 0.0f);
    out->z.assign(pixels, std::numeric_limits<float>::infinity());
    out->normal.assign(o.layers.normal ? pixels * 3 : 0, 0.0f);
    out->voxel.assign(o.layers.voxel ? pixels * 3 : 0, 0.0f);
    // Tiles do not overlap: the render threads write disjoint pixels.
    fo.on_tile = [out, &o](const TileRect& r, const TileBuffer& b) -> Status {
      auto at = [&b](int c, int x, int y) { return b.ch[c][size_t(y) * size_t(b.size) + x]; };
      for (int y = 0; y < r.h; ++y)
        for (int x = 0; x < r.w; ++x) {
          const size_t p = size_t(r.y0 + y) * size_t(out->width) + size_t(r.x0 + x);
          for (int c = 0; c < 4; ++c) out->rgba[p * 4 + c] = at(kChR + c, x, y);
          out->z[p] = at(kChZ, x, y);
          for (int c = 0; o.layers.normal && c < 3; ++c)
            out->normal[p * 3 + c] = at(kChNx + c, x, y);
          for (int c = 0; o.layers.voxel && c < 3; ++c)
            out->voxel[p * 3 + c] = at(kChVi + c, x, y);
        }
      return OkStatus();
    };
  }
  FrameStats stats;
  VOX_RETURN_IF_ERROR(RenderFrame(*renderer, fo, &stats));
  const double frame_seconds = phase.Lap();
  if (!o.preview_path.empty()) {
    SetExrThreads(threads);  // the preview reads a row of tiles per call: decoded in parallel
    VOX_RETURN_IF_ERROR(WritePngPreview(o.exr_path, o.preview_path));
  }
  const double preview_seconds = phase.Lap();
  if (!o.stats_path.empty() || out != nullptr) {
    nlohmann::json json = nlohmann::json::parse(
        StatsJson(*renderer, stats,
                  {{"open_seconds", open_seconds},
                   {"setup_seconds", setup_seconds},
                   {"frame_seconds", frame_seconds},
                   {"preview_seconds", preview_seconds},
                   {"total_seconds", total.Seconds()}}));
    nlohmann::json memory = nlohmann::json::parse(budget.ToJson());
    memory["source"] = process.source;
    memory["table_slots"] = 1 << slot_bits;
    memory["io_threads"] = io_threads;
    memory["max_brick_bytes"] = volume->brick_sizes().max_decoded;
    json["memory"] = memory;
    if (renderer->lod() != nullptr) json["lod"] = LodStatsJson(*renderer, stats, lod_stores, lod_start);
    if (out) out->stats_json = json.dump(2);
    if (!o.stats_path.empty())
      VOX_RETURN_IF_ERROR(WriteFileAtomically(o.stats_path, json.dump(2) + "\n"));
  }
  if (!o.quiet) {
    uint64_t total = 0;
    for (int k = 0; k < kNumRayKinds; ++k) total += stats.counters.rays[k];
    fprintf(
        o.log,
        "vox-render: %s (%dx%d, part %s, split %s, passes %s): %.3f s, %llu rays, %.2fM rays/s\n",
        o.exr_path.c_str(), camera.width, camera.height, o.part.ToString().c_str(),
        renderer->SplitString().c_str(), renderer->passes().ToString().c_str(),
        stats.render_seconds, (unsigned long long)total,
        stats.render_seconds > 0 ? total / stats.render_seconds / 1e6 : 0.0);
  }
  return OkStatus();
}

}  // namespace vox

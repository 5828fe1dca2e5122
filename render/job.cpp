#include "render/job.h"

#include <algorithm>
#include <cmath>
#include <charconv>
#include <malloc.h>
#include <sys/statvfs.h>
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
#include "storage/file.h"
#include "storage/lod.h"
#include "storage/path_identity.h"
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
  j["silhouette_grid"] = r.silhouette_grid();
  j["refined_pixels"] = st.counters.lod.refined_pixels;
  j["refine_rays"] = st.counters.lod.refine_rays;
  j["border_rays"] = st.counters.lod.border_rays;
  nlohmann::json stops = nlohmann::json::object(), paged = nlohmann::json::array(),
                 bytes = nlohmann::json::array(), pages = nlohmann::json::array();
  for (int l = 0; l <= kMaxLevels; ++l)
    if (st.counters.lod.stops[l] > 0) stops[std::to_string(l)] = st.counters.lod.stops[l];
  uint64_t total_paged = st.cache_end.misses - st.cache_start.misses;
  uint64_t total_bytes = st.cache_end.bytes_read - st.cache_start.bytes_read;
  uint64_t total_pages = st.cache_end.table_pages_read - st.cache_start.table_pages_read;
  paged.push_back(total_paged);
  bytes.push_back(total_bytes);
  pages.push_back(total_pages);
  for (size_t i = 0; i < levels.size(); ++i) {
    const CacheStats e = levels[i]->cache_stats();
    paged.push_back(e.misses - start[i].misses);
    bytes.push_back(e.bytes_read - start[i].bytes_read);
    pages.push_back(e.table_pages_read - start[i].table_pages_read);
    total_pages += e.table_pages_read - start[i].table_pages_read;
    total_paged += e.misses - start[i].misses;
    total_bytes += e.bytes_read - start[i].bytes_read;
  }
  j["stops_by_level"] = stops;
  j["bricks_paged_by_level"] = paged;
  j["brick_bytes_read_by_level"] = bytes;
  j["bricks_paged_total"] = total_paged;
  j["brick_bytes_read_total"] = total_bytes;
  j["table_pages_read_by_level"] = pages;  // brick table pages (storage/FORMAT.md)
  j["table_pages_read_total"] = total_pages;
  return j;
}

// An exact frame of a store without a pyramid: when the voxels where the
// volume begins are much smaller than a pixel of the central ray, says once
// that level of detail would read fewer bricks, and how to add the pyramid.
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
            std::tan(cam.HorizontalFovDeg() * (3.14159265358979323846 / 360.0)) / cam.width;
  else
    pixel = cam.ortho_width / cam.width;
  const double voxels = pixel / m.voxel_size;
  if (!(voxels >= 4.0)) return;  // "much smaller": at least level 2
  if (LodMaxLevel(m.levels) < 1) return;
  fprintf(log,
          "vox-render: about %.1f voxels fall across a pixel at the volume's front; with a "
          "level-of-detail pyramid (vox-ingest --add-lod %s) the frame would read fewer bricks\n",
          voxels, dir.c_str());
}

// The options that need no file: refused before anything is opened.
Status CheckJobOptions(const RenderJobOptions& options) {
  if (!options.preview_path.empty() && options.exr_path.empty())
    return InvalidArgumentError("--preview needs an EXR output (-o)");
  if (!options.preview_path.empty() && !options.part.whole())
    return InvalidArgumentError(
        "--preview needs the whole image; with --tiles, preview the vox-merge output");
  // Output paths are checked before any work: a bad one fails in a moment,
  // not after the render. The files are written atomically at the end.
  for (const std::string* path : {&options.exr_path, &options.preview_path, &options.stats_path,
                                  &options.save_camera_path})
    if (!path->empty()) VOX_RETURN_IF_ERROR(CheckOutputPath(*path));
  if (!options.exr_path.empty()) VOX_RETURN_IF_ERROR(CheckExtension("-o", options.exr_path, ".exr"));
  if (!options.preview_path.empty())
    VOX_RETURN_IF_ERROR(CheckExtension("--preview", options.preview_path, ".png"));
  // No output may be an input (a store file, the camera, the scene) or
  // another output.
  std::vector<NamedPath> inputs = StoreInputs(options.store_dir);
  inputs.push_back({"camera", options.camera_path});
  inputs.push_back({"scene", options.scene_path});
  VOX_RETURN_IF_ERROR(CheckDistinctPaths(inputs, {{"-o", options.exr_path},
                                                  {"--preview", options.preview_path},
                                                  {"--stats", options.stats_path},
                                                  {"--save-cam", options.save_camera_path}}));
  if (options.threads < 0)
    return InvalidArgumentError("threads " + std::to_string(options.threads) +
                                ": must not be negative (0: all cores)");
  if (options.io_threads < 1 || options.io_threads > kMaxIoThreads)
    return InvalidArgumentError("--io-threads " + std::to_string(options.io_threads) +
                                ": must be 1.." + std::to_string(kMaxIoThreads));
  if (options.lod && !(*options.lod >= 0 && std::isfinite(*options.lod)))
    return InvalidArgumentError("--lod " + std::to_string(*options.lod) +
                                ": must be finite and >= 0 (0: exact)");
  if (options.silhouette_grid < 0 || options.silhouette_grid > kMaxSilhouetteGrid)
    return InvalidArgumentError("--silhouette-aa " + std::to_string(options.silhouette_grid) +
                                ": must be 0 (off) or 1.." + std::to_string(kMaxSilhouetteGrid));
  if (options.single_step && !options.split.empty())
    return InvalidArgumentError("--split and --single-step both choose the split; give one");
  return OkStatus();
}

// A frame over kMaxPixelsUnlessAllowed is refused without --allow-huge;
// the EXR's uncompressed size (an upper bound) is printed and must fit the
// free space of its directory.
Status CheckFrameSize(const RenderJobOptions& options, const Camera& camera) {
  // The layout's own limit first (the most tiles an image may have).
  VOX_RETURN_IF_ERROR(CheckTileCount(camera.width, camera.height,
                                     std::clamp(options.tile_size, kMinTileSize, kMaxTileSize)));
  const int64_t pixels = int64_t(camera.width) * int64_t(camera.height);
  const std::string size = std::to_string(camera.width) + "x" + std::to_string(camera.height);
  if (pixels > kMaxPixelsUnlessAllowed && !options.allow_huge)
    return InvalidArgumentError("a " + size + " frame has " + std::to_string(pixels) +
                                " pixels, more than " + std::to_string(kMaxPixelsUnlessAllowed) +
                                "; pass --allow-huge to render it");
  if (options.exr_path.empty()) return OkStatus();
  const int bytes_per_pixel = (options.layers.float_color ? 16 : 8) + 4 +
                              (options.layers.normal ? 12 : 0) + (options.layers.voxel ? 12 : 0);
  const double fraction = options.part.whole() ? 1.0 : 1.0 / options.part.count;
  const uint64_t estimate = uint64_t(double(pixels) * bytes_per_pixel * fraction);
  if (!options.quiet)
    fprintf(options.log, "vox-render: %s: %s, at most %.1f MiB\n", options.exr_path.c_str(),
            size.c_str(), double(estimate) / double(kMiB));
  std::string dir, name;
  SplitPath(options.exr_path, &dir, &name);
  struct statvfs vfs;
  if (statvfs(dir.c_str(), &vfs) != 0) return OkStatus();
  const uint64_t free_bytes = uint64_t(vfs.f_bavail) * uint64_t(vfs.f_frsize);
  if (estimate > free_bytes)
    return ResourceExhaustedError("-o " + options.exr_path + ": the " + size + " image may take " +
                                  std::to_string(estimate >> 20) + " MiB and " + dir + " has " +
                                  std::to_string(free_bytes >> 20) + " MiB free");
  return OkStatus();
}

// The camera: --cam's file, the camera JSON text, or the default framing of
// the volume's world box; then --size and --view, which override it.
StatusOr<Camera> JobCamera(const RenderJobOptions& options, const StoreMeta& meta) {
  glm::dvec3 lo, hi;
  WorldBounds(meta, &lo, &hi);
  Camera camera = DefaultCamera(lo, hi, options.default_width, options.default_height);
  std::string source = "camera";
  if (!options.camera_path.empty()) {
    VOX_ASSIGN_OR_RETURN(camera, LoadCamera(options.camera_path));
    source = options.camera_path;
  } else if (!options.camera_json.empty()) {
    VOX_ASSIGN_OR_RETURN(camera, ParseCamera(options.camera_json, "camera"));
  }
  if (options.size_given) {
    camera.width = options.default_width;
    camera.height = options.default_height;
    VOX_RETURN_IF_ERROR(camera.Finalize("--size"));
  }
  if (options.view) {
    VOX_ASSIGN_OR_RETURN(camera,
                         OrbitCamera(camera, lo, hi, options.view->first, options.view->second));
  }
  // A given camera may be anywhere; the default one and --view's are near.
  const bool given = !options.camera_path.empty() || !options.camera_json.empty();
  if (given && !options.view)
    VOX_RETURN_IF_ERROR(CheckCameraDistance(camera, lo, hi).WithContext(source));
  return camera;
}

// --stats "camera": the camera used, as cam.json, and where its parts came from.
nlohmann::json CameraStatsJson(const RenderJobOptions& options, const Camera& camera) {
  nlohmann::json j = nlohmann::json::parse(camera.ToJson());
  const bool given = !options.camera_path.empty() || !options.camera_json.empty();
  j["source"] = {
      {"camera", !options.camera_path.empty() ? options.camera_path
                 : given                     ? std::string("camera JSON")
                                             : std::string("default")},
      {"size", options.size_given ? "--size" : given ? "camera" : "default"},
      {"view", options.view ? nlohmann::json{options.view->first, options.view->second}
                            : nlohmann::json(nullptr)}};
  return j;
}

StatusOr<Scene> JobScene(const RenderJobOptions& options) {
  if (!options.scene_path.empty()) return LoadScene(options.scene_path);
  if (!options.scene_json.empty()) return ParseScene(options.scene_json, "scene");
  return Scene();
}

// The I/O threads reading ahead (--prefetch): each holds a run of bricks in
// its buffer and in the page cache (2 x kPrefetchRunBytes), so at most one
// per 32 MiB of budget, and a small budget keeps its memory for the cache.
int IoThreadsFor(const RenderJobOptions& options, const ProcessBudget& process) {
  if (!options.prefetch) return 0;
  return int(std::clamp<uint64_t>(process.bytes / (32 * kMiB), 1, uint64_t(options.io_threads)));
}

// The memory budget's split between the stores, the threads' pinned bricks
// and the buffers. With LOD, the levels finer than any ray of this camera can
// stop at get no more than the minimum cache (a full view of a huge volume
// uses none of the base's bricks), unless the scene refracts (refraction is
// exact); silhouette antialiasing stops G times finer.
StatusOr<MemoryBudget> JobBudget(const RenderJobOptions& options, const RenderStores& stores,
                                 const Camera& camera, const Scene& scene,
                                 const ProcessBudget& process, int threads, int io_threads) {
  BudgetInputs inputs;
  inputs.image_width = camera.width;
  inputs.image_height = camera.height;
  inputs.tile_size = std::clamp(options.tile_size, kMinTileSize, kMaxTileSize);
  inputs.threads = threads;
  inputs.channels = 5 + options.layers.ExtraChannels();
  inputs.cache_override = uint64_t(options.cache_mb) << 20;
  inputs.io_threads = io_threads;
  inputs.read_window_bytes = options.read_windows ? kMaxReadWindowBytes : 0;
  if (options.keep_image)
    inputs.process_base += uint64_t(camera.width) * uint64_t(camera.height) *
                           uint64_t(inputs.channels) * sizeof(float);
  int first_level = 0;
  if (stores.lod > 0 && !SceneRefracts(scene)) {
    std::vector<Volume*> levels(stores.levels.begin(), stores.levels.end());
    VOX_ASSIGN_OR_RETURN(const LodTracer tracer,
                         LodTracer::Create(stores.base.get(), levels, stores.lod));
    glm::dvec3 lo, hi;
    WorldBounds(stores.base->meta(), &lo, &hi);
    const Cone cone = PrimaryConeOf(camera, stores.base->meta().voxel_size);
    first_level = tracer.FirstLevelSeen(camera, cone, lo, hi);
    if (options.silhouette_grid > 0)
      first_level = std::max(0, first_level - std::ilogb(options.silhouette_grid));
  }
  return BudgetStores(stores.base.get(), stores.levels, process.bytes, inputs, first_level);
}

StatusOr<RenderOptions> JobRenderOptions(const RenderJobOptions& options, const RenderStores& stores,
                                         const MemoryBudget& budget) {
  RenderOptions render;
  render.layers = options.layers;
  render.beam = options.beam;
  const int levels = stores.base->meta().levels;
  if (options.single_step) {
    render.n1 = levels;
  } else if (!options.split.empty()) {
    VOX_ASSIGN_OR_RETURN(render.n1, ParseSplit(options.split, levels));
  }
  int slot_bits = 0;
  while ((2 << slot_bits) <= budget.pins_per_thread) ++slot_bits;
  render.table_slot_bits = slot_bits;
  if (options.prefetch) {
    Store* store = stores.base.get();
    render.read_ahead = [store](std::span<const uint32_t> ids) { store->Prefetch(ids); };
  }
  render.lod = stores.lod;
  render.silhouette_grid = options.silhouette_grid;
  for (Store* level : stores.levels) render.lod_levels.push_back(level);
  return render;
}

// The level-of-detail setting in effect, as the EXR header and --stats
// name it: "0 (exact)" or "F" with how it was chosen and whether
// silhouettes are antialiased. vox-merge refuses parts that differ in it.
std::string LodSetting(const RenderStores& stores, const Renderer& renderer) {
  if (renderer.lod() == nullptr)
    return stores.lod_default ? "0 (exact: the store has no pyramid)" : "0 (exact)";
  char factor[32];
  snprintf(factor, sizeof factor, "%g", stores.lod);
  const int g = renderer.silhouette_grid();
  return std::string(factor) + (stores.lod_default ? " (default)" : "") +
         (g > 0 ? ", silhouettes from " + std::to_string(g) + "x" + std::to_string(g) + " rays"
                : "");
}

FrameOptions JobFrameOptions(const RenderJobOptions& options, const RenderStores& stores,
                             const Renderer& renderer, const MemoryBudget& budget, int threads) {
  FrameOptions frame;
  frame.exr_path = options.exr_path;
  frame.threads = threads;
  if (options.prefetch) {
    Store* store = stores.base.get();
    frame.prefetch = [store](std::span<const uint32_t> ids) { store->Prefetch(ids); };
    frame.prefetch_backlog = [store] { return store->PrefetchBacklog(); };
    // Half the cache may hold bricks read ahead (Store::Prefetch); the scout
    // waits at a quarter so the store seldom has to drop requests.
    frame.prefetch_limit = budget.brick_cache / 4;
  }
  frame.tile_size = options.tile_size;
  frame.part = options.part;
  frame.compression = options.compression;
  frame.progress = ChooseProgressMode(options.log, options.quiet);
  frame.progress_out = options.log;
  frame.attrs["vox:store"] = options.store_dir;
  char id[17];
  snprintf(id, sizeof id, "%016llx", (unsigned long long)stores.base->store_id());
  frame.attrs["vox:storeId"] = id;  // vox-merge refuses parts of different stores
  const StoreMeta& meta = stores.base->meta();
  frame.attrs["vox:grid"] = meta.grid_name;
  frame.attrs["vox:source"] = meta.source_file;
  frame.attrs["vox:lod"] = LodSetting(stores, renderer);
  return frame;
}

// Keeps the rendered pixels in `out` (RenderJobOutput), tile by tile.
void KeepImage(const Camera& camera, const ImageLayers& layers, RenderJobOutput* out,
               FrameOptions* frame) {
  const size_t pixels = size_t(camera.width) * size_t(camera.height);
  out->width = camera.width;
  out->height = camera.height;
  out->rgba.assign(pixels * 4, 0.0f);
  out->z.assign(pixels, std::numeric_limits<float>::infinity());
  out->normal.assign(layers.normal ? pixels * 3 : 0, 0.0f);
  out->voxel.assign(layers.voxel ? pixels * 3 : 0, 0.0f);
  out->position.assign(layers.position ? pixels * 3 : 0, 0.0f);
  out->distance.assign(layers.distance ? pixels : 0, std::numeric_limits<float>::infinity());
  // Tiles do not overlap: the render threads write disjoint pixels.
  frame->on_tile = [out, layers](const TileRect& r, const TileBuffer& b) -> Status {
    auto at = [&b](int c, int x, int y) { return b.ch[c][size_t(y) * size_t(b.size) + x]; };
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x) {
        const size_t p = size_t(r.y0 + y) * size_t(out->width) + size_t(r.x0 + x);
        for (int c = 0; c < 4; ++c) out->rgba[p * 4 + c] = at(kChR + c, x, y);
        out->z[p] = at(kChZ, x, y);
        for (int c = 0; layers.normal && c < 3; ++c) out->normal[p * 3 + c] = at(kChNx + c, x, y);
        for (int c = 0; layers.voxel && c < 3; ++c) out->voxel[p * 3 + c] = at(kChVi + c, x, y);
        for (int c = 0; layers.position && c < 3; ++c)
          out->position[p * 3 + c] = at(kChPx + c, x, y);
        if (layers.distance) out->distance[p] = at(kChDist, x, y);
      }
    return OkStatus();
  };
}

// The --stats document: the frame's (StatsJson), the memory budget and the
// level of detail in effect.
std::string JobStatsJson(const RenderJobOptions& options, const Renderer& renderer,
                         const FrameStats& stats,
                         const RenderStores& stores, const std::vector<CacheStats>& lod_start,
                         const ProcessBudget& process, const MemoryBudget& budget,
                         int slot_bits, int io_threads,
                         const std::vector<std::pair<std::string, double>>& timings) {
  nlohmann::json json = nlohmann::json::parse(StatsJson(renderer, stats, timings));
  nlohmann::json memory = nlohmann::json::parse(budget.ToJson());
  memory["source"] = process.source;
  memory["table_slots"] = 1 << slot_bits;
  memory["io_threads"] = io_threads;
  memory["max_brick_bytes"] = stores.base->brick_sizes().max_decoded;
  json["memory"] = memory;
  nlohmann::json lod = {{"factor", stores.lod}, {"default", stores.lod_default},
                        {"setting", LodSetting(stores, renderer)}};
  if (renderer.lod() != nullptr) lod.update(LodStatsJson(renderer, stats, stores.levels, lod_start));
  json["lod"] = lod;
  json["camera"] = CameraStatsJson(options, renderer.camera());
  return json.dump(2);
}

// The PNG preview's background: the scene's, behind a premultiplied EXR;
// none when the EXR has it already (Scene::background_in_exr).
PreviewBackground PreviewBackgroundOf(const Renderer& renderer) {
  if (renderer.scene().background_in_exr) return nullptr;
  return [&renderer](int x, int y, float rgb[3]) {
    const glm::dvec3 bg = renderer.Background(renderer.camera().PixelRay(x + 0.5, y + 0.5).dir);
    for (int c = 0; c < 3; ++c) rgb[c] = float(bg[c]);
  };
}

void PrintSummary(const RenderJobOptions& options, const Renderer& renderer,
                  const FrameStats& stats) {
  const Camera& camera = renderer.camera();
  uint64_t rays = 0;
  for (int k = 0; k < kNumRayKinds; ++k) rays += stats.counters.rays[k];
  fprintf(options.log,
          "vox-render: %s (%dx%d, part %s, split %s, passes %s, lod %s): %.3f s, %llu rays, "
          "%.2fM rays/s\n",
          options.exr_path.c_str(), camera.width, camera.height, options.part.ToString().c_str(),
          renderer.SplitString().c_str(), renderer.passes().ToString().c_str(),
          renderer.lod() ? "on" : "off (exact)", stats.render_seconds, (unsigned long long)rays,
          stats.render_seconds > 0 ? rays / stats.render_seconds / 1e6 : 0.0);
}

}  // namespace

StatusOr<RenderStores> OpenRenderStores(const std::string& dir, std::optional<double> lod,
                                        const OpenOptions& open) {
  RenderStores stores;
  VOX_ASSIGN_OR_RETURN(stores.base, Store::Open(dir, open));
  stores.lod_default = !lod.has_value();
  if (lod) {
    stores.lod = *lod;
  } else if (HasLod(dir)) {
    stores.lod = kDefaultLodFactor;
  }
  if (stores.lod > 0) {
    auto pyramid = LodPyramid::Open(dir, *stores.base, open);
    if (!pyramid.ok())
      return pyramid.status().WithContext(stores.lod_default ? "level of detail (--lod 0: exact)"
                                                             : "--lod");
    stores.pyramid = std::move(pyramid).value();
    for (int l = 1; l <= stores.pyramid->max_level(); ++l)
      stores.levels.push_back(stores.pyramid->level(l));
  }
  // Open's scratch (the index blocks, as large as the resident top) is
  // free but stays in the main heap, which the render threads' allocator
  // arenas do not reuse: give it back so the budget's estimate holds.
  malloc_trim(0);
  return stores;
}

Status RunRenderJob(const RenderJobOptions& options, RenderJobOutput* out) {
  const Stopwatch total;
  Stopwatch phase;
  VOX_RETURN_IF_ERROR(CheckJobOptions(options));
  VOX_ASSIGN_OR_RETURN(const ProcessBudget process, ChooseProcessBudget(options.memory_bytes));
  const int io_threads = IoThreadsFor(options, process);
  OpenOptions open;
  // The budget bounds the cache (BudgetStore sets it once the resident top
  // is known); opening with it gives the cache its number of shards.
  open.cache_bytes = options.cache_mb > 0 ? options.cache_mb << 20 : process.bytes;
  open.io_threads = std::max(io_threads, 1);
  open.read_windows = options.read_windows;
  open.budget_bytes = process.bytes;
  VOX_ASSIGN_OR_RETURN(RenderStores stores, OpenRenderStores(options.store_dir, options.lod, open));
  const double open_seconds = phase.Lap();

  VOX_ASSIGN_OR_RETURN(const Camera camera, JobCamera(options, stores.base->meta()));
  VOX_RETURN_IF_ERROR(CheckFrameSize(options, camera));
  VOX_ASSIGN_OR_RETURN(const Scene scene, JobScene(options));
  const int threads =
      options.threads > 0 ? options.threads : int(std::max(1u, std::thread::hardware_concurrency()));
  // The budget's split, before any output exists: a store whose resident
  // top does not fit fails here, saying how much it needs.
  const bool keep = options.keep_image && out != nullptr;
  RenderJobOptions budgeted = options;
  budgeted.keep_image = keep;
  VOX_ASSIGN_OR_RETURN(const MemoryBudget budget, JobBudget(budgeted, stores, camera, scene,
                                                           process, threads, io_threads));
  if (!options.quiet)
    fprintf(options.log, "vox-render: memory %s; %s\n", process.ToString().c_str(),
            budget.ToString().c_str());
  VOX_ASSIGN_OR_RETURN(const RenderOptions render_options, JobRenderOptions(options, stores, budget));
  VOX_ASSIGN_OR_RETURN(auto renderer,
                       Renderer::Create(stores.base.get(), camera, scene, render_options));
  if (stores.lod == 0.0 && stores.lod_default && !options.quiet)
    LodHint(options.store_dir, *stores.base, camera, options.log);
  const double setup_seconds = phase.Lap();
  std::vector<CacheStats> lod_start;
  for (Store* level : stores.levels) lod_start.push_back(level->cache_stats());

  FrameOptions frame = JobFrameOptions(options, stores, *renderer, budget, threads);
  if (keep) KeepImage(camera, options.layers, out, &frame);
  frame.interrupted = options.interrupted;
  // The EXR, the preview and the stats are published together, once all
  // are written: a failed one leaves every earlier output as it was.
  OutputGroup outputs;
  frame.outputs = &outputs;
  FrameStats stats;
  VOX_RETURN_IF_ERROR(RenderFrame(*renderer, frame, &stats));
  const double frame_seconds = phase.Lap();
  if (!options.preview_path.empty()) {
    SetExrThreads(threads);  // the preview reads a row of tiles per call: decoded in parallel
    VOX_RETURN_IF_ERROR(WritePngPreview(options.exr_path, options.preview_path,
                                        PreviewBackgroundOf(*renderer), &outputs,
                                        outputs.TempOf(options.exr_path)));
  }
  const double preview_seconds = phase.Lap();
  if (!options.stats_path.empty() || out != nullptr) {
    const std::string json = JobStatsJson(
        options, *renderer, stats, stores, lod_start, process, budget,
        render_options.table_slot_bits, io_threads,
        {{"open_seconds", open_seconds},
         {"setup_seconds", setup_seconds},
         {"frame_seconds", frame_seconds},
         {"preview_seconds", preview_seconds},
         {"total_seconds", total.Seconds()}});
    if (out) out->stats_json = json;
    if (!options.stats_path.empty())
      VOX_RETURN_IF_ERROR(outputs.AddBytes(options.stats_path, json + "\n"));
  }
  if (!options.save_camera_path.empty())
    VOX_RETURN_IF_ERROR(outputs.AddBytes(options.save_camera_path, camera.ToJson() + "\n"));
  if (options.interrupted) VOX_RETURN_IF_ERROR(options.interrupted());
  VOX_RETURN_IF_ERROR(outputs.Commit());
  if (!options.quiet) PrintSummary(options, *renderer, stats);
  return OkStatus();
}

}  // namespace vox

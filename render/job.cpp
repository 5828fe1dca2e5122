#include "render/job.h"

#include <algorithm>
#include <cmath>
#include <charconv>
#include <malloc.h>
#include <limits>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/util/stopwatch.h"
#include "core/tracer.h"
#include "render/camera.h"
#include "render/frame.h"
#include "render/grid_transform.h"
#include "render/internal/job_plan.h"
#include "render/lod.h"
#include "render/renderer.h"
#include "render/scene.h"
#include "core/util/atomic_file.h"
#include "core/util/file.h"
#include "storage/buffer_pool.h"
#include "storage/lod.h"
#include "core/util/memory_budget.h"
#include "core/util/path_identity.h"
#include "storage/store.h"
#include "storage/store_budget.h"

namespace vox {
namespace {

using job_internal::CheckFrameSize;
using job_internal::FrameOutputs;
using job_internal::JobSequence;

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

// --stats "camera": the camera used, as cam.json, and where its parts came
// from: the given camera (its index in an array) or the default one,
// --size, --view, and the turntable's turn.
nlohmann::json CameraStatsJson(const RenderJobOptions& options, const JobSequence& seq,
                               int number, const Camera& camera) {
  nlohmann::json j = nlohmann::json::parse(camera.ToJson());
  const bool given = !seq.given.empty();
  j["source"] = {
      {"camera", !options.camera_path.empty() ? options.camera_path
                 : given                     ? std::string("camera JSON")
                                             : std::string("default")},
      {"index", seq.given.size() > 1 ? nlohmann::json(number - 1) : nlohmann::json(nullptr)},
      {"size", options.size_given ? "--size" : given ? "camera" : "default"},
      {"view", options.view ? nlohmann::json{options.view->first, options.view->second}
                            : nlohmann::json(nullptr)},
      {"turntable", options.turntable > 0
                        ? nlohmann::json{{"frames", options.turntable},
                                         {"turn_deg", 360.0 * (number - 1) / options.turntable}}
                        : nlohmann::json(nullptr)}};
  return j;
}

StatusOr<Scene> JobScene(const RenderJobOptions& options) {
  if (!options.scene_path.empty()) return LoadScene(options.scene_path);
  if (!options.scene_json.empty()) return ParseScene(options.scene_json, "scene");
  return Scene();
}

// The memory budget's split between the stores, the threads' pinned bricks
// and the buffers. With LOD, the levels finer than any ray of this camera can
// stop at get no more than the minimum cache (a full view of a huge volume
// uses none of the base's bricks), unless the scene refracts (refraction is
// exact); silhouette antialiasing stops G times finer.
// `open_levels`: every pyramid level open, budgeted even when this frame is
// exact (a session keeps them, and their caches, between frames).
StatusOr<MemoryBudget> JobBudget(const RenderJobOptions& options, const RenderStores& stores,
                                 const std::vector<Store*>& open_levels,
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
  return BudgetStores(stores.base.get(), open_levels, process.bytes, inputs, first_level);
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
  // The scout traces the base store exactly (Renderer::FirstBricks): with a
  // level of detail in effect the rays stop at coarser levels, and it read
  // base bricks no ray needed (the 8192^3 sphere's full view: 302 MB read
  // against 202, 62,108 bricks paged against 27,130), so then it stays off.
  if (options.prefetch && renderer.lod() == nullptr) {
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

// What every frame of a run shares: the opened stores (and so their brick
// caches), the scene, the process budget and the threads.
struct JobRun {
  const RenderJobOptions& options;
  const JobSequence& sequence;
  const RenderStores& stores;
  const Scene& scene;
  const ProcessBudget& process;
  int threads = 1, io_threads = 0;
  bool keep = false;  // the image goes into `out` (one frame)
  RenderJobOutput* out = nullptr;
  uint64_t anon_at_start = 0;  // the process's anonymous memory before the stores opened
  const std::vector<Store*>* open_levels = nullptr;  // RenderSession::all_levels
};

// The heap watch's target for a frame with `budget`: the budget less its
// headroom, plus what the process held before the job beyond the budget's
// estimate of a bare process (a Python session's arrays, a test harness),
// which the budget did not plan for either: the watch guards the budget's
// own lines against the allocator's growth, not against the host process.
uint64_t HeapTarget(const JobRun& run, const MemoryBudget& budget) {
  const uint64_t before = run.anon_at_start > budget.process_base
                              ? run.anon_at_start - budget.process_base
                              : 0;
  return budget.total - budget.headroom + before;
}

// The --stats document: the frame's (StatsJson), its number in the
// sequence, the memory budget, the level of detail in effect and the camera.
std::string JobStatsJson(const JobRun& run, int number, const Renderer& renderer,
                         const FrameStats& stats, const std::vector<CacheStats>& lod_start,
                         const MemoryBudget& budget, int slot_bits,
                         const std::vector<std::pair<std::string, double>>& timings) {
  const RenderStores& stores = run.stores;
  nlohmann::json json = nlohmann::json::parse(StatsJson(renderer, stats, timings));
  json["frame"] = {{"number", number},
                   {"count", run.sequence.count},
                   {"first", run.sequence.range.first},
                   {"last", run.sequence.range.last}};
  nlohmann::json memory = nlohmann::json::parse(budget.ToJson());
  memory["source"] = run.process.source;
  memory["table_slots"] = 1 << slot_bits;
  memory["io_threads"] = run.io_threads;
  memory["max_brick_bytes"] = stores.base->brick_sizes().max_decoded;
  memory["process"] = nlohmann::json::parse(ReadProcessMemory().ToJson());
  memory["brick_pool"] = nlohmann::json::parse(ReadBrickPoolStats().ToJson());
  memory["held_at_start"] = run.process.held;
  memory["address_space_left"] = run.process.address_space;
  memory["heap_watch"] = {{"target", HeapWatch::Process().target()},
                          {"given_up", HeapWatch::Process().given_up()},
                          {"anon_at_start", run.anon_at_start}};
  json["memory"] = memory;
  nlohmann::json lod = {{"factor", stores.lod}, {"default", stores.lod_default},
                        {"setting", LodSetting(stores, renderer)}};
  if (renderer.lod() != nullptr) lod.update(LodStatsJson(renderer, stats, stores.levels, lod_start));
  json["lod"] = lod;
  json["camera"] = CameraStatsJson(run.options, run.sequence, number, renderer.camera());
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

void PrintSummary(const RenderJobOptions& options, const std::string& exr_path,
                  const Renderer& renderer, const FrameStats& stats) {
  const Camera& camera = renderer.camera();
  uint64_t rays = 0;
  for (int k = 0; k < kNumRayKinds; ++k) rays += stats.counters.rays[k];
  fprintf(options.log,
          "vox-render: %s (%dx%d, part %s, split %s, passes %s, lod %s): %.3f s, %llu rays, "
          "%.2fM rays/s\n",
          exr_path.c_str(), camera.width, camera.height, options.part.ToString().c_str(),
          renderer.SplitString().c_str(), renderer.passes().ToString().c_str(),
          renderer.lod() ? "on" : "off (exact)", stats.render_seconds, (unsigned long long)rays,
          stats.render_seconds > 0 ? rays / stats.render_seconds / 1e6 : 0.0);
}

// Renders frame `files.number` of the run with `camera` and publishes its
// outputs together; `first`: the run's first frame (it prints the budget
// and hints, and its --stats has the store's open time `open_seconds`).
// `save_camera`: the --save-cam text this frame publishes (empty: none).
Status RenderJobFrame(const JobRun& run, const FrameOutputs& files, const Camera& camera,
                      bool first, double open_seconds, const std::string& save_camera) {
  const RenderJobOptions& options = run.options;
  const Stopwatch total;
  Stopwatch phase;
  const bool say = !options.quiet;
  if (say && run.sequence.count > 1) {
    fprintf(options.log, "vox-render: frame %d/%d", files.number, run.sequence.count);
    if (run.sequence.frames() < run.sequence.count)
      fprintf(options.log, " (%d of %d in this run)", files.number - run.sequence.range.first + 1,
              run.sequence.frames());
    fprintf(options.log, "\n");
  }
  VOX_RETURN_IF_ERROR(CheckFrameSize(options, files.exr, camera, /*say=*/false));

  // The budget's split, before any output exists: a store whose resident
  // top does not fit fails here, saying how much it needs. Each frame sets
  // the caches' capacities again (the same for frames of one size and
  // distance), keeping the bricks they hold.
  RenderJobOptions budgeted = options;
  budgeted.keep_image = run.keep;
  VOX_ASSIGN_OR_RETURN(const MemoryBudget budget,
                       JobBudget(budgeted, run.stores, *run.open_levels, camera, run.scene,
                                 run.process, run.threads, run.io_threads));
  if (say && first)
    fprintf(options.log, "vox-render: memory %s; %s\n", run.process.ToString().c_str(),
            budget.ToString().c_str());
  // Anonymous memory past what the budget planned (all but its headroom) is
  // the allocator's: the stores give that much of their caches up.
  HeapWatch::Process().SetTarget(HeapTarget(run, budget));
  VOX_ASSIGN_OR_RETURN(const RenderOptions render_options,
                       JobRenderOptions(options, run.stores, budget));
  VOX_ASSIGN_OR_RETURN(auto renderer, Renderer::Create(run.stores.base.get(), camera, run.scene,
                                                       render_options));
  if (first && run.stores.lod == 0.0 && run.stores.lod_default && say)
    LodHint(options.store_dir, *run.stores.base, camera, options.log);
  const double setup_seconds = phase.Lap();
  std::vector<CacheStats> lod_start;
  for (Store* level : run.stores.levels) lod_start.push_back(level->cache_stats());

  // The frame, into the EXR's temporary (and the kept image).
  FrameOptions frame = JobFrameOptions(options, run.stores, *renderer, budget, run.threads);
  frame.exr_path = files.exr;
  // Which frame of the sequence: with the camera and the store's id, what
  // --skip-done checks.
  frame.attrs["vox:frame"] =
      std::to_string(files.number) + "/" + std::to_string(run.sequence.count);
  if (options.skip_done && !files.exr.empty()) {
    std::vector<std::string> others;
    for (const std::string* p : {&files.preview, &files.stats, &files.save_camera})
      if (!p->empty()) others.push_back(*p);
    const std::string why = FrameDoneReason(*renderer, frame, files.exr, others);
    if (why.empty()) {
      if (say)
        fprintf(options.log,
                "vox-render: %s is done (this frame of this job, every tile read): skipped\n",
                files.exr.c_str());
      return OkStatus();
    }
    if (say) fprintf(options.log, "vox-render: rendering %s: %s\n", files.exr.c_str(), why.c_str());
  }
  if (run.keep) KeepImage(camera, options.layers, run.out, &frame);
  frame.interrupted = options.interrupted;
  // The EXR, the preview and the stats are published together, once all
  // are written: a failed one leaves every earlier output as it was.
  OutputGroup outputs;
  frame.outputs = &outputs;
  FrameStats stats;
  VOX_RETURN_IF_ERROR(RenderFrame(*renderer, frame, &stats));
  const double frame_seconds = phase.Lap();

  // The preview, the stats and the camera, then the publication.
  if (!files.preview.empty()) {
    SetExrThreads(run.threads);  // the preview reads a row of tiles per call: decoded in parallel
    VOX_RETURN_IF_ERROR(WritePngPreview(files.exr, files.preview, PreviewBackgroundOf(*renderer),
                                        &outputs, outputs.TempOf(files.exr)));
  }
  const double preview_seconds = phase.Lap();
  if (!files.stats.empty() || run.out != nullptr) {
    const std::string json =
        JobStatsJson(run, files.number, *renderer, stats, lod_start, budget,
                     render_options.table_slot_bits,
                     {{"open_seconds", first ? open_seconds : 0.0},
                      {"setup_seconds", setup_seconds},
                      {"frame_seconds", frame_seconds},
                      {"preview_seconds", preview_seconds},
                      {"total_seconds", total.Seconds() + (first ? open_seconds : 0.0)}});
    if (run.out) run.out->stats_json = json;
    if (!files.stats.empty()) VOX_RETURN_IF_ERROR(outputs.AddBytes(files.stats, json + "\n"));
  }
  if (!files.save_camera.empty() && !save_camera.empty())
    VOX_RETURN_IF_ERROR(outputs.AddBytes(files.save_camera, save_camera));
  if (options.interrupted) VOX_RETURN_IF_ERROR(options.interrupted());
  VOX_RETURN_IF_ERROR(outputs.Commit());
  if (say) PrintSummary(options, files.exr, *renderer, stats);
  return OkStatus();
}

}  // namespace

Status RunRenderJob(const RenderJobOptions& options, RenderJobOutput* out,
                    RenderSession* session) {
  using namespace job_internal;
  // Each frame sets the heap watch's target from its budget; once the job
  // ends, stores opened outside a job (the Python module's) are not watched.
  struct UnwatchHeap {
    ~UnwatchHeap() { HeapWatch::Process().SetTarget(0); }
  } unwatch_heap;
  // The options, the frames and every frame's outputs, before any work.
  VOX_RETURN_IF_ERROR(CheckJobOptions(options));
  const bool keep = options.keep_image && out != nullptr;
  VOX_ASSIGN_OR_RETURN(JobSequence sequence, PlanSequence(options, keep));
  VOX_RETURN_IF_ERROR(CheckJobOutputs(options, sequence));

  // The store and its pyramid, opened once for every frame (or kept open by
  // the caller's session).
  std::unique_ptr<RenderSession> own;
  const bool opened_now = session == nullptr;
  if (opened_now) {
    VOX_ASSIGN_OR_RETURN(own, OpenRenderSession(options));
    session = own.get();
  }
  VOX_RETURN_IF_ERROR(SetSessionLod(options, session));
  const RenderStores& stores = session->stores;
  const double open_seconds = opened_now ? session->open_seconds : 0.0;

  // The cameras (every frame of the run checked) and the scene, then the
  // frames in order, each frame's camera and paths made when it comes.
  VOX_RETURN_IF_ERROR(PrepareCameras(options, stores.base->meta(), &sequence));
  VOX_ASSIGN_OR_RETURN(const Scene scene, JobScene(options));
  JobRun run{options, sequence, stores, scene, session->process};
  run.threads =
      options.threads > 0 ? options.threads : int(std::max(1u, std::thread::hardware_concurrency()));
  run.io_threads = session->io_threads;
  run.keep = keep;
  run.out = out;
  run.anon_at_start = session->anon_at_start;
  run.open_levels = &session->all_levels;
  for (int n = sequence.range.first; n <= sequence.range.last; ++n) {
    const FrameOutputs files = FrameFiles(options, sequence, n);
    VOX_RETURN_IF_ERROR(CheckFrameFiles(options, sequence, files));
    if (options.on_outputs) {
      std::vector<std::string> paths;
      for (const std::string* p : {&files.exr, &files.preview, &files.stats, &files.save_camera})
        if (!p->empty()) paths.push_back(*p);
      options.on_outputs(paths);
    }
    VOX_ASSIGN_OR_RETURN(const Camera camera, FrameCamera(options, sequence, n));
    VOX_ASSIGN_OR_RETURN(const std::string save_camera, SaveCameraText(options, sequence, n));
    VOX_RETURN_IF_ERROR(RenderJobFrame(run, files, camera, n == sequence.range.first,
                                       open_seconds, save_camera));
    // A frame that turns over the brick cache leaves freed pages scattered
    // in the allocator's heaps; without this, a sequence's resident memory
    // crept up 3-4 MiB a frame past the budget (the 8192^3 sphere's exact
    // turntable was OOM-killed in 512 MiB at frame 22).
    if (sequence.frames() > 1) malloc_trim(0);
  }
  return OkStatus();
}

}  // namespace vox

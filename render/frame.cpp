#include "render/frame.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/stopwatch.h"

namespace vox {
namespace {

struct Worker {
  std::unique_ptr<Renderer::ThreadState, Renderer::ThreadStateDeleter> state;
  TileBuffer buf;
  RenderCounters counters;
  double write_seconds = 0;
};

}  // namespace

std::string ProgressLine(const ProgressSnapshot& s, double elapsed) {
  double frac = s.tiles_total > 0 ? double(s.tiles_done) / double(s.tiles_total) : 1.0;
  double rate = elapsed > 0 ? double(s.rays) / elapsed : 0.0;
  uint64_t lookups = s.cache_hits + s.cache_misses;
  std::string cache =
      lookups > 0
          ? std::to_string(int(std::lround(100.0 * double(s.cache_hits) / double(lookups)))) + "%"
          : "-";
  double left = frac > 0 ? elapsed * (1.0 - frac) / frac : INFINITY;
  char buf[256];
  snprintf(buf, sizeof buf,
           "tiles %lld/%lld (%3.0f%%)  %s rays/s  cache hits %s  elapsed %s  left %s",
           (long long)s.tiles_done, (long long)s.tiles_total, 100.0 * frac,
           Progress::Count(rate).c_str(), cache.c_str(), Progress::Duration(elapsed).c_str(),
           Progress::Duration(left).c_str());
  return buf;
}

Status RenderFrame(const Renderer& renderer, const FrameOptions& options, FrameStats* stats) {
  const Camera& cam = renderer.camera();
  Volume* volume = renderer.volume();
  if (options.tile_size < kMinTileSize || options.tile_size > kMaxTileSize)
    return InvalidArgumentError("tile size " + std::to_string(options.tile_size) + ": must be in " +
                                std::to_string(kMinTileSize) + ".." +
                                std::to_string(kMaxTileSize));
  VOX_RETURN_IF_ERROR(CheckTileCount(cam.width, cam.height, options.tile_size));
  if (options.threads < 0)
    return InvalidArgumentError("threads " + std::to_string(options.threads) +
                                ": must not be negative (0: all cores)");
  const TileLayout layout(cam.width, cam.height, options.tile_size);
  int64_t begin = 0, end = 0;
  layout.PartRange(options.part, &begin, &end);

  ExrAttributes attrs = options.attrs;
  attrs["vox:camera"] = cam.ToJson();
  attrs["vox:scene"] = renderer.scene().ToJson();
  attrs["vox:split"] = renderer.SplitString();
  attrs["vox:passes"] = renderer.passes().ToString();
  attrs["vox:part"] = options.part.ToString();
  attrs["vox:tileOrder"] = "morton";
  attrs["vox:store"] = attrs.count("vox:store") ? attrs["vox:store"] : volume->description();
  attrs["software"] = "vox-render";

  const ImageLayers& img_layers = renderer.layers();
  std::unique_ptr<TiledExrWriter> writer;
  int threads = options.threads > 0 ? options.threads
                                    : int(std::max(1u, std::thread::hardware_concurrency()));
  if (!options.exr_path.empty()) {
    // Tiles are written one per call as they finish: OpenEXR's pool would
    // hand each tile to a pool thread and back (measured: 2-3x the write
    // time of compressing in the calling thread, docs/benchmarks.md).
    SetExrThreads(0);
    const ExrCompression compression = options.compression.value_or(
        options.part.whole() ? ExrCompression::kRle : ExrCompression::kNone);
    const ExrCameraAttributes camera_attrs = StandardCameraAttributes(cam);
    VOX_ASSIGN_OR_RETURN(writer, TiledExrWriter::Create(options.exr_path, cam.width, cam.height,
                                                        options.tile_size, img_layers, attrs,
                                                        compression, &camera_attrs));
  }
  stats->threads = threads;
  stats->tiles_total = end - begin;
  stats->cache_start = volume->cache_stats();

  Progress progress(options.progress, options.progress_out);
  std::atomic<int64_t> cursor{begin};
  std::atomic<int64_t> done{0};
  std::atomic<uint64_t> rays{0};
  std::atomic<uint64_t> brick_entries{0};  // bricks rays entered (traversal brick fetches)
  std::atomic<bool> abort{false};
  std::mutex err_mu;
  Status first_error;
  tbb::enumerable_thread_specific<Worker> workers([&] {
    Worker w;
    w.buf.Allocate(options.tile_size, img_layers);
    w.state = renderer.NewThreadState();
    return w;
  });

  auto snapshot = [&] {
    ProgressSnapshot s;
    s.tiles_done = done.load();
    s.tiles_total = end - begin;
    s.rays = rays.load();
    // Hit rate over the bricks rays entered: those served by the threads'
    // tables or the shared cache, against those paged in (the shared cache's
    // own hits are few when the threads' tables serve most entries).
    CacheStats c = volume->cache_stats();
    const uint64_t misses = c.misses - stats->cache_start.misses;
    const uint64_t entries = std::max(brick_entries.load(), misses);
    s.cache_hits = entries - misses;
    s.cache_misses = misses;
    return s;
  };

  // The scout: a thread that walks the tile order ahead of the workers,
  // finds the bricks each tile's primary rays enter first (the resident top
  // only, no brick read) and asks for them, so the volume reads them while
  // the workers trace. It stays at most prefetch_tiles tiles ahead and waits
  // while the bytes read ahead and not yet used exceed prefetch_limit.
  std::atomic<bool> scout_stop{false};
  std::thread scout;
  if (options.prefetch) {
    scout = std::thread([&] {
      try {
        std::vector<uint32_t> ids;
        const int64_t ahead = std::max<int64_t>(1, options.prefetch_tiles);
        for (int64_t j = begin; j < end; ++j) {
          for (;;) {
            if (scout_stop.load() || abort.load()) return;
            const bool far = j >= cursor.load() + ahead;
            const bool full = options.prefetch_backlog && options.prefetch_limit > 0 &&
                              options.prefetch_backlog() > options.prefetch_limit;
            if (!far && !full) break;
            std::this_thread::sleep_for(std::chrono::microseconds(200));
          }
          j = std::max(j, cursor.load());  // tiles the workers started need no scouting
          if (j >= end) return;
          ids.clear();
          renderer.FirstBricks(layout.order()[size_t(j)], options.prefetch_stride, &ids);
          if (!ids.empty()) options.prefetch(ids);
        }
      } catch (const std::exception&) {
        // Prefetching is an optimisation: without it, the workers read what they need.
      }
    });
  }
  struct JoinScout {
    std::atomic<bool>& stop;
    std::thread& t;
    ~JoinScout() {
      stop = true;
      if (t.joinable()) t.join();
    }
  } join_scout{scout_stop, scout};

  Stopwatch frame_clock;
  tbb::task_arena arena(threads);
  arena.execute([&] {
    tbb::parallel_for(0, threads, [&](int) {
      Worker& w = workers.local();
      // Each worker hands its counters to the frame's under err_mu, which
      // the calling thread takes after the loop: the hand-over is ordered
      // for ThreadSanitizer too (an uninstrumented TBB's join is not).
      auto hand_over = [&] {
        std::lock_guard<std::mutex> lock(err_mu);
        stats->counters.Add(w.counters);
        w.counters = RenderCounters();
        stats->write_seconds += w.write_seconds;
        w.write_seconds = 0;
      };
      for (;;) {
        if (abort.load(std::memory_order_relaxed)) return hand_over();
        const int64_t i = cursor.fetch_add(1);
        if (i >= end) return hand_over();
        const TileRect& rect = layout.order()[size_t(i)];
        uint64_t rays_before = 0;
        for (int k = 0; k < kNumRayKinds; ++k) rays_before += w.counters.rays[k];
        const uint64_t entries_before = w.counters.trace.brick_fetches;
        Status s = renderer.RenderTile(rect, &w.buf, &w.counters, w.state.get());
        const Stopwatch tw;
        if (s.ok() && writer) s = writer->WriteTile(rect, w.buf);
        w.write_seconds += tw.Seconds();
        if (s.ok() && options.on_tile) s = options.on_tile(rect, w.buf);
        if (!s.ok()) {
          std::lock_guard<std::mutex> lock(err_mu);
          if (first_error.ok())
            first_error = s.WithContext("tile (" + std::to_string(rect.tx) + ", " +
                                        std::to_string(rect.ty) + ")");
          abort = true;
        }
        if (!s.ok()) return hand_over();
        uint64_t rays_after = 0;
        for (int k = 0; k < kNumRayKinds; ++k) rays_after += w.counters.rays[k];
        rays.fetch_add(rays_after - rays_before, std::memory_order_relaxed);
        brick_entries.fetch_add(w.counters.trace.brick_fetches - entries_before,
                                std::memory_order_relaxed);
        done.fetch_add(1, std::memory_order_relaxed);
        const ProgressSnapshot now = snapshot();
        progress.Update(uint64_t(now.tiles_done), uint64_t(now.tiles_total),
                        [&](double elapsed) { return ProgressLine(now, elapsed); });
      }
    });
  });
  scout_stop = true;
  if (scout.joinable()) scout.join();
  stats->render_seconds = frame_clock.Lap();
  Status error;
  {
    std::lock_guard<std::mutex> lock(err_mu);  // after the workers' hand-overs
    error = first_error;
  }
  stats->tiles = done.load();
  stats->cache_end = volume->cache_stats();
  if (!error.ok()) {
    if (writer) writer->Abandon();  // an earlier file at exr_path stays intact
    return error;
  }
  const ProgressSnapshot last = snapshot();
  progress.Finish(uint64_t(last.tiles_done), uint64_t(last.tiles_total),
                  [&](double elapsed) { return ProgressLine(last, elapsed); });
  if (!writer) return OkStatus();
  nlohmann::json timings{{"render_seconds", stats->render_seconds},
                         {"write_seconds", stats->write_seconds},
                         {"threads", threads}};
  VOX_RETURN_IF_ERROR(writer->Finish(stats->render_seconds, timings.dump()));
  stats->close_seconds = frame_clock.Seconds();
  return OkStatus();
}

std::string StatsJson(const Renderer& renderer, const FrameStats& st,
                      const std::vector<std::pair<std::string, double>>& extra_timings) {
  using nlohmann::json;
  const RenderCounters& c = st.counters;
  json rays;
  uint64_t total = 0;
  for (int k = 0; k < kNumRayKinds; ++k) {
    rays[RayKindName(k)] = c.rays[k];
    total += c.rays[k];
  }
  rays["total"] = total;
  const TraceCounters& t = c.trace;
  json j;
  j["image"] = {{"width", renderer.camera().width},
                {"height", renderer.camera().height},
                {"pixels", c.pixels},
                {"hit_pixels", c.hit_pixels},
                {"tiles", st.tiles},
                {"tiles_total", st.tiles_total},
                {"samples_per_pixel", renderer.scene().samples_per_pixel}};
  j["passes"] = {
      {"shading", renderer.passes().shading},       {"shadows", renderer.passes().shadows},
      {"reflection", renderer.passes().reflection}, {"refraction", renderer.passes().refraction},
      {"volume", renderer.passes().volume},         {"scattering", renderer.passes().scattering}};
  j["split"] = {{"n1", renderer.n1()}, {"n2", renderer.n2()}};
  j["rays"] = rays;
  j["dda"] = {{"moves", t.total_moves()},
              {"moves_x", t.moves[0]},
              {"moves_y", t.moves[1]},
              {"moves_z", t.moves[2]},
              {"driving_moves", t.driving_moves},
              {"passive_moves", t.passive_moves},
              {"skips", t.skips},
              {"cells_visited", t.cells_visited},
              {"transitions", t.transitions},
              {"brick_fetches", t.brick_fetches},
              {"traversals", t.rays},
              {"hits", t.hits}};
  j["attribute_lookups"] = c.attribute_lookups;
  j["deferred_pixels"] = c.deferred_pixels;
  const CacheStats& a = st.cache_start;
  const CacheStats& b = st.cache_end;
  j["cache"] = {{"hits", b.hits - a.hits},
                {"misses", b.misses - a.misses},
                {"bricks_paged_in", b.misses - a.misses + b.prefetched - a.prefetched},
                {"evictions", b.evictions - a.evictions},
                {"bytes_decompressed", b.bytes_decompressed - a.bytes_decompressed},
                {"bytes_resident", b.bytes_resident},
                {"capacity", b.capacity},
                {"prefetched", b.prefetched - a.prefetched},
                {"prefetch_hits", b.prefetch_hits - a.prefetch_hits},
                {"prefetch_dropped", b.prefetch_dropped - a.prefetch_dropped},
                {"prefetch_failed", b.prefetch_failed - a.prefetch_failed}};
  // Bytes the frame read: those the store asked for, and those the process
  // read from storage (/proc/self/io read_bytes: page cache misses).
  j["io"] = {{"brick_bytes_read", b.bytes_read - a.bytes_read},
             {"read_bytes", b.process_read_bytes - a.process_read_bytes},
             {"windows_read", b.windows_read - a.windows_read},
             {"window_bytes", b.window_bytes}};
  json timings{{"render_seconds", st.render_seconds},
               {"write_seconds", st.write_seconds},
               {"close_seconds", st.close_seconds}};
  for (const auto& [name, secs] : extra_timings) timings[name] = secs;
  j["timings"] = timings;
  j["threads"] = st.threads;
  if (st.render_seconds > 0) {
    j["rates"] = {{"rays_per_second", double(total) / st.render_seconds},
                  {"dda_moves_per_second", double(t.total_moves()) / st.render_seconds}};
  }
  return j.dump(2);
}

}  // namespace vox

#include "render/frame.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/util/parallel.h"
#include "core/util/stopwatch.h"

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

// The EXR header's vox attributes: what was rendered, how, and from what.
ExrAttributes FrameAttributes(const Renderer& renderer, const FrameOptions& options) {
  ExrAttributes attrs = options.attrs;
  attrs["vox:camera"] = renderer.camera().ToJson();
  attrs["vox:scene"] = renderer.scene().ToJson();
  attrs["vox:split"] = renderer.SplitString();
  attrs["vox:passes"] = renderer.passes().ToString();
  attrs["vox:part"] = options.part.ToString();
  attrs["vox:tileOrder"] = "morton";
  attrs["vox:store"] =
      attrs.count("vox:store") ? attrs["vox:store"] : renderer.volume()->description();
  attrs["software"] = "vox-render";
  return attrs;
}

std::string FrameDoneReason(const Renderer& renderer, const FrameOptions& options,
                            const std::string& exr, const std::vector<std::string>& others) {
  std::error_code ec;
  if (!std::filesystem::exists(exr, ec)) return "no " + exr;
  StatusOr<ExrInfo> info = ReadExrInfo(exr);
  if (!info.ok()) return info.status().message();
  for (const auto& [key, value] : FrameAttributes(renderer, options)) {
    auto it = info->attrs.find(key);
    if (it == info->attrs.end()) return exr + " has no " + key;
    if (it->second != value) return exr + " has another " + key;
  }
  std::vector<std::string> channels;
  for (int c = 0; c < kNumChannels; ++c)
    if (renderer.layers().Has(c)) channels.push_back(ChannelName(c));
  std::vector<std::string> have = info->channels;
  std::sort(channels.begin(), channels.end());
  std::sort(have.begin(), have.end());
  if (have != channels || info->float_color != renderer.layers().float_color)
    return exr + " has other channels";
  if (Status s = VerifyExrTiles(exr); !s.ok()) return s.message();
  const auto exr_time = std::filesystem::last_write_time(exr, ec);
  if (ec) return exr + ": " + ec.message();
  for (const std::string& p : others) {
    const auto size = std::filesystem::file_size(p, ec);
    if (ec || size == 0) return "no " + p;
    if (std::filesystem::last_write_time(p, ec) < exr_time || ec)
      return p + " is older than " + exr;
  }
  return "";
}

namespace {

// The tiled EXR the frame's tiles go to (none without options.exr_path).
StatusOr<std::unique_ptr<TiledExrWriter>> OpenFrameWriter(const Renderer& renderer,
                                                          const FrameOptions& options) {
  if (options.exr_path.empty()) return std::unique_ptr<TiledExrWriter>();
  // Tiles are written one per call as they finish: OpenEXR's pool would
  // hand each tile to a pool thread and back (measured: 2-3x the write
  // time of compressing in the calling thread).
  SetExrThreads(0);
  const Camera& cam = renderer.camera();
  const ExrCompression compression = options.compression.value_or(
      options.part.whole() ? ExrCompression::kRle : ExrCompression::kNone);
  const ExrCameraAttributes camera_attrs = StandardCameraAttributes(cam);
  return TiledExrWriter::Create(options.exr_path, cam.width, cam.height, options.tile_size,
                                renderer.layers(), FrameAttributes(renderer, options),
                                compression, &camera_attrs);
}

// One frame in flight: the tile cursor the render threads pull from, their
// progress, the first error, and the prefetch scout.
class FrameRun {
 public:
  FrameRun(const Renderer& renderer, const FrameOptions& options, const TileLayout& layout,
           int64_t begin, int64_t end, TiledExrWriter* writer, FrameStats* stats)
      : renderer_(renderer), options_(options), layout_(layout), begin_(begin), end_(end),
        writer_(writer), stats_(stats), progress_(options.progress, options.progress_out),
        cursor_(begin) {}
  ~FrameRun() { StopScout(); }

  // The scout: a thread that walks the tile order ahead of the workers,
  // finds the bricks each tile's primary rays enter first (the resident top
  // only, no brick read) and asks for them, so the volume reads them while
  // the workers trace. It stays at most prefetch_tiles tiles ahead and waits
  // while the bytes read ahead and not yet used exceed prefetch_limit.
  void StartScout() {
    if (options_.prefetch) scout_ = std::thread([this] { Scout(); });
  }
  void StopScout() {
    scout_stop_ = true;
    if (scout_.joinable()) scout_.join();
  }

  // Renders tiles until none is left or one fails (every thread of the frame).
  void Work(Worker& w);

  // The first error, once the workers are done.
  Status Error() {
    std::lock_guard<std::mutex> lock(mu_);  // after the workers' hand-overs
    return first_error_;
  }
  int64_t tiles_done() const { return done_.load(); }
  void FinishProgress() {
    const ProgressSnapshot last = Snapshot();
    progress_.Finish(uint64_t(last.tiles_done), uint64_t(last.tiles_total),
                     [&](double elapsed) { return ProgressLine(last, elapsed); });
  }

 private:
  void Scout();
  // Renders tile i into w's buffer and hands it to the writer and on_tile.
  Status RenderOne(Worker& w, int64_t i);
  // The worker's counters go to the frame's under mu_, which the calling
  // thread takes after the loop.
  void HandOver(Worker& w) {
    std::lock_guard<std::mutex> lock(mu_);
    stats_->counters.Add(w.counters);
    w.counters = RenderCounters();
    stats_->write_seconds += w.write_seconds;
    w.write_seconds = 0;
  }
  ProgressSnapshot Snapshot() const {
    ProgressSnapshot s;
    s.tiles_done = done_.load();
    s.tiles_total = end_ - begin_;
    s.rays = rays_.load();
    // Hit rate over the bricks rays entered: those served by the threads'
    // tables or the shared cache, against those paged in (the shared cache's
    // own hits are few when the threads' tables serve most entries).
    const CacheStats c = renderer_.volume()->cache_stats();
    const uint64_t misses = c.misses - stats_->cache_start.misses;
    const uint64_t entries = std::max(brick_entries_.load(), misses);
    s.cache_hits = entries - misses;
    s.cache_misses = misses;
    return s;
  }
  static uint64_t TotalRays(const RenderCounters& c) {
    uint64_t total = 0;
    for (int k = 0; k < kNumRayKinds; ++k) total += c.rays[k];
    return total;
  }

  const Renderer& renderer_;
  const FrameOptions& options_;
  const TileLayout& layout_;
  const int64_t begin_, end_;
  TiledExrWriter* writer_;
  FrameStats* stats_;
  Progress progress_;
  std::atomic<int64_t> cursor_;
  std::atomic<int64_t> done_{0};
  std::atomic<uint64_t> rays_{0};
  std::atomic<uint64_t> brick_entries_{0};  // bricks rays entered (traversal brick fetches)
  std::atomic<bool> abort_{false};
  std::mutex mu_;
  Status first_error_;
  std::atomic<bool> scout_stop_{false};
  std::thread scout_;
};

void FrameRun::Scout() {
  try {
    std::vector<uint32_t> ids;
    const int64_t ahead = std::max<int64_t>(1, options_.prefetch_tiles);
    for (int64_t j = begin_; j < end_; ++j) {
      for (;;) {
        if (scout_stop_.load() || abort_.load()) return;
        const bool far = j >= cursor_.load() + ahead;
        const bool full = options_.prefetch_backlog && options_.prefetch_limit > 0 &&
                          options_.prefetch_backlog() > options_.prefetch_limit;
        if (!far && !full) break;
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
      j = std::max(j, cursor_.load());  // tiles the workers started need no scouting
      if (j >= end_) return;
      ids.clear();
      renderer_.FirstBricks(layout_.order()[size_t(j)], options_.prefetch_stride, &ids);
      if (!ids.empty()) options_.prefetch(ids);
    }
  } catch (const std::exception&) {
    // Prefetching is an optimisation: without it, the workers read what they need.
  }
}

Status FrameRun::RenderOne(Worker& w, int64_t i) {
  const TileRect& rect = layout_.order()[size_t(i)];
  if (options_.interrupted) VOX_RETURN_IF_ERROR(options_.interrupted());
  Status s = renderer_.RenderTile(rect, &w.buf, &w.counters, w.state.get());
  const Stopwatch write_clock;
  if (s.ok() && writer_ != nullptr) s = writer_->WriteTile(rect, w.buf);
  w.write_seconds += write_clock.Seconds();
  if (s.ok() && options_.on_tile) s = options_.on_tile(rect, w.buf);
  if (s.ok()) return s;
  return s.WithContext("tile (" + std::to_string(rect.tx) + ", " + std::to_string(rect.ty) + ")");
}

void FrameRun::Work(Worker& w) {
  for (;;) {
    if (abort_.load(std::memory_order_relaxed)) return HandOver(w);
    const int64_t i = cursor_.fetch_add(1);
    if (i >= end_) return HandOver(w);
    const uint64_t rays_before = TotalRays(w.counters);
    const uint64_t entries_before = w.counters.trace.brick_fetches;
    const Status s = RenderOne(w, i);
    if (!s.ok()) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (first_error_.ok()) first_error_ = s;
      }
      abort_ = true;
      return HandOver(w);
    }
    rays_.fetch_add(TotalRays(w.counters) - rays_before, std::memory_order_relaxed);
    brick_entries_.fetch_add(w.counters.trace.brick_fetches - entries_before,
                             std::memory_order_relaxed);
    done_.fetch_add(1, std::memory_order_relaxed);
    const ProgressSnapshot now = Snapshot();
    progress_.Update(uint64_t(now.tiles_done), uint64_t(now.tiles_total),
                     [&](double elapsed) { return ProgressLine(now, elapsed); });
  }
}

Status CheckFrameOptions(const Camera& cam, const FrameOptions& options) {
  if (options.tile_size < kMinTileSize || options.tile_size > kMaxTileSize)
    return InvalidArgumentError("tile size " + std::to_string(options.tile_size) + ": must be in " +
                                std::to_string(kMinTileSize) + ".." +
                                std::to_string(kMaxTileSize));
  VOX_RETURN_IF_ERROR(CheckTileCount(cam.width, cam.height, options.tile_size));
  if (options.threads < 0)
    return InvalidArgumentError("threads " + std::to_string(options.threads) +
                                ": must not be negative (0: all cores)");
  return OkStatus();
}

}  // namespace

Status RenderFrame(const Renderer& renderer, const FrameOptions& options, FrameStats* stats) {
  const Camera& cam = renderer.camera();
  VOX_RETURN_IF_ERROR(CheckFrameOptions(cam, options));
  const TileLayout layout(cam.width, cam.height, options.tile_size);
  int64_t begin = 0, end = 0;
  layout.PartRange(options.part, &begin, &end);
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<TiledExrWriter> writer, OpenFrameWriter(renderer, options));
  const int threads = options.threads > 0 ? options.threads
                                          : int(std::max(1u, std::thread::hardware_concurrency()));
  stats->threads = threads;
  stats->tiles_total = end - begin;
  stats->cache_start = renderer.volume()->cache_stats();

  FrameRun run(renderer, options, layout, begin, end, writer.get(), stats);
  run.StartScout();
  Stopwatch frame_clock;
  // One worker per thread, each with its own buffer and thread state.
  try {
    RunWorkers(threads, [&](int) {
      Worker w;
      w.buf.Allocate(options.tile_size, renderer.layers());
      w.state = renderer.NewThreadState();
      run.Work(w);
    });
  } catch (...) {  // out of memory for a worker's buffer: the scout stops first
    run.StopScout();
    throw;
  }
  run.StopScout();
  stats->render_seconds = frame_clock.Lap();
  const Status error = run.Error();
  stats->tiles = run.tiles_done();
  stats->cache_end = renderer.volume()->cache_stats();
  if (!error.ok()) {
    if (writer) writer->Abandon();  // an earlier file at exr_path stays intact
    return error;
  }
  run.FinishProgress();
  if (!writer) return OkStatus();
  nlohmann::json timings{{"render_seconds", stats->render_seconds},
                         {"write_seconds", stats->write_seconds},
                         {"threads", threads}};
  VOX_RETURN_IF_ERROR(writer->Finish(stats->render_seconds, timings.dump(), options.outputs));
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
                {"given_to_heap", b.given_to_heap - a.given_to_heap},
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
             {"table_pages_read", b.table_pages_read - a.table_pages_read},
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

// vox-storage-bench: writes a store from a generated shape, then measures
// store size per voxel, brick decompression throughput (1 and N threads) and
// the brick cache's hit rate while tracing a 512^2 perspective image with
// several cache budgets.
//
//   vox-storage-bench [--shape sphere:512] [--brick-level L] [--zstd-level Z]
//                     [--normal-bits B] [--threads N] [--keep DIR]
//   vox-storage-bench --store DIR [--threads N] [--cache-mb M]
// --keep DIR leaves the written store at DIR (useful to test readers without
// an ingest); otherwise it is written to a temporary directory and removed.
// --store DIR measures an existing store (nothing else held in memory) and
// reports peak anonymous resident memory while tracing, against the budget.
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <cinttypes>
#include <thread>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <unistd.h>

#include "core/shapes.h"
#include "core/util/stopwatch.h"
#include "core/tracer.h"
#include "storage/store.h"
#include "storage/store_info.h"
#include "storage/store_writer.h"
#include "tools/common/flags.h"

namespace {

struct Options {
  std::string shape = "sphere:512", keep, store;
  int brick_level = -1, zstd_level = 3, threads = 2, normal_bits = 16;
  double cache_mb = -1;  // trace with this budget only (default: 200%, 50%, 10%, 2% of the bricks)
};

// RssAnon of this process in bytes (Linux), 0 if unknown.
uint64_t RssAnon() {
  FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  uint64_t kb = 0;
  while (std::fgets(line, sizeof(line), f))
    if (std::sscanf(line, "RssAnon: %" SCNu64 " kB", &kb) == 1) break;
  std::fclose(f);
  return kb << 10;
}

// Samples RssAnon every 2 ms while alive; peak() is the largest seen.
class RssSampler {
 public:
  RssSampler() : thread_([this] {
      while (!stop_) {
        uint64_t r = RssAnon();
        if (r > peak_) peak_ = r;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    }) {}
  ~RssSampler() {
    stop_ = true;
    thread_.join();
  }
  uint64_t peak() const { return peak_; }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> peak_{0};
  std::thread thread_;
};

int Fail(const std::string& m) {
  std::fprintf(stderr, "vox-storage-bench: %s\n", m.c_str());
  return 1;
}

// Writes o.shape as a store at *dir_out (a temporary directory when empty).
int WriteShapeStore(Options& o, std::string* dir_out, std::string* tmp_out) {
  auto vol = vox::GenerateShape(o.shape);
  if (!vol.ok()) return Fail(vol.status().ToString());
  const int levels = vol->levels;
  if (o.brick_level < 0) o.brick_level = std::max(1, levels - 5);
  const double n = double(int64_t(1) << levels), c = n / 2;
  vox::StoreMeta meta;
  meta.source_file = "generated:" + o.shape;
  meta.grid_name = "shape";
  meta.grid_class = vox::GridClass::kLevelSet;
  meta.levels = levels;
  meta.brick_level = o.brick_level;
  meta.has_normal = true;
  meta.build_options = "vox-storage-bench --shape " + o.shape;

  std::string& dir = *dir_out;
  std::string& tmp = *tmp_out;
  if (dir.empty()) {
    tmp = (std::filesystem::temp_directory_path() / ("vox_bench_" + std::to_string(getpid())))
              .string();
    std::filesystem::create_directories(tmp);
    dir = tmp + "/store";
  }

  // Group by brick (normals from the centre, as a sphere's gradient); untimed.
  std::vector<std::pair<glm::u64vec3, std::vector<vox::BrickVoxel>>> bricks;
  {
    const int sub = levels - o.brick_level;
    std::vector<vox::LeafPoint> pts = vol->voxels;
    std::sort(pts.begin(), pts.end(), vox::MortonLess);
    size_t i = 0;
    const uint64_t lm = (uint64_t(1) << sub) - 1;
    while (i < pts.size()) {
      glm::u64vec3 bc(pts[i].x >> sub, pts[i].y >> sub, pts[i].z >> sub);
      std::vector<vox::BrickVoxel> vs;
      for (; i < pts.size() && glm::u64vec3(pts[i].x >> sub, pts[i].y >> sub, pts[i].z >> sub) == bc; ++i) {
        vox::BrickVoxel v;
        v.x = uint32_t(pts[i].x & lm);
        v.y = uint32_t(pts[i].y & lm);
        v.z = uint32_t(pts[i].z & lm);
        glm::vec3 d(float(pts[i].x + 0.5 - c), float(pts[i].y + 0.5 - c), float(pts[i].z + 0.5 - c));
        v.attr.normal = d / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
        vs.push_back(v);
      }
      bricks.push_back({bc, std::move(vs)});
    }
  }
  // Write: AddBrick from all threads, then Finish (fsync, rename).
  const vox::Stopwatch t0;
  {
    vox::WriteOptions wo;
    wo.zstd_level = o.zstd_level;
    wo.force = true;
    wo.normal_bits = o.normal_bits;
    auto w = vox::StoreWriter::Create(dir, meta, wo);
    if (!w.ok()) return Fail(w.status().ToString());
    std::atomic<bool> failed{false};
    tbb::parallel_for(size_t(0), bricks.size(), [&](size_t k) {
      vox::Status s = (*w)->AddBrick(bricks[k].first, std::move(bricks[k].second));
      if (!s.ok()) {
        std::fprintf(stderr, "vox-storage-bench: %s\n", s.ToString().c_str());
        failed = true;
      }
    });
    if (failed) return 1;
    vox::Status s = (*w)->Finish();
    if (!s.ok()) return Fail(s.ToString());
  }
  double write_s = t0.Seconds();
  auto info = vox::InspectStore(dir, false);
  if (!info.ok()) return Fail(info.status().ToString());
  std::printf("%s", vox::FormatStoreInfo(*info).c_str());
  std::printf("write: %.2f s, %.1f M voxels/s (%d threads, zstd level %d, including fsync)\n",
              write_s, double(vol->voxels.size()) / write_s / 1e6, o.threads, o.zstd_level);

  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  vox::FlagReader flags(argc, argv);
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (a != "--shape" && a != "--brick-level" && a != "--zstd-level" && a != "--threads" &&
        a != "--keep" && a != "--store" && a != "--cache-mb" && a != "--normal-bits") {
      std::fprintf(stderr, "usage: vox-storage-bench [--shape S] [--brick-level L] "
                           "[--zstd-level Z] [--normal-bits B] [--threads N] [--keep DIR]\n"
                           "       vox-storage-bench --store DIR [--threads N] [--cache-mb M]\n");
      return 2;
    }
    const std::optional<std::string> v = flags.Value();
    if (!v) {
      std::fprintf(stderr, "vox-storage-bench: %s needs a value\n", a.c_str());
      return 2;
    }
    bool ok = true;
    if (a == "--shape") o.shape = *v;
    else if (a == "--brick-level") ok = vox::ParseInt(*v, -1000000, 1000000, &o.brick_level);
    else if (a == "--zstd-level") ok = vox::ParseInt(*v, -1000000, 1000000, &o.zstd_level);
    else if (a == "--threads") ok = vox::ParseInt(*v, -1000000, 1000000, &o.threads);
    else if (a == "--keep") o.keep = *v;
    else if (a == "--store") o.store = *v;
    else if (a == "--cache-mb") ok = vox::ParseDouble(*v, &o.cache_mb);
    else ok = vox::ParseInt(*v, -1000000, 1000000, &o.normal_bits);
    if (!ok) {
      std::fprintf(stderr, "vox-storage-bench: %s '%s': not a number\n", a.c_str(), v->c_str());
      return 2;
    }
  }
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, std::max(1, o.threads));
  std::string dir = o.store.empty() ? o.keep : o.store;
  std::string tmp;
  if (o.store.empty()) {
    int r = WriteShapeStore(o, &dir, &tmp);
    if (r != 0) return r;
  }
  auto info = vox::InspectStore(dir, false);
  if (!info.ok()) return Fail(info.status().ToString());
  if (!o.store.empty()) std::printf("%s", vox::FormatStoreInfo(*info).c_str());
  const int levels = info->meta.levels;
  const double n = double(int64_t(1) << levels), c = n / 2;

  // Decompression throughput: a 1-byte cache makes every fetch decompress.
  for (int threads : {1, o.threads}) {
    if (o.cache_mb > 0) break;  // a single traced budget: keep the process clean
    vox::OpenOptions oo;
    oo.cache_bytes = 1;
    auto store = vox::Store::Open(dir, oo);
    if (!store.ok()) return Fail(store.status().ToString());
    const uint32_t bricks = uint32_t((*store)->meta().brick_count);
    const int rounds = std::max<int>(1, int(20000 / std::max<uint32_t>(1, bricks)));
    std::atomic<bool> failed{false};
    const vox::Stopwatch t1;
    tbb::task_arena arena(threads);
    arena.execute([&] {
      tbb::parallel_for(0, int(bricks) * rounds, [&](int k) {
        if (!(*store)->FetchBrick(uint32_t(k % int(bricks))).ok()) failed = true;
      });
    });
    double s = t1.Seconds();
    if (failed) return Fail("a brick fetch failed");
    vox::CacheStats cs = (*store)->cache_stats();
    std::printf("decompress (%d thread%s): %.0f bricks/s, %.0f MB/s decompressed, %.1f M voxels/s\n",
                threads, threads > 1 ? "s" : "", double(cs.misses) / s,
                double(cs.bytes_decompressed) / s / 1e6,
                double(info->meta.voxel_count) * rounds / s / 1e6);
  }

  // Cache hit rate while tracing a 512^2 perspective image, with Attributes().
  const int W = 512, H = 512;
  std::vector<double> fracs = {2.0, 0.5, 0.1, 0.02};
  if (o.cache_mb > 0) fracs = {o.cache_mb * (1 << 20) / double(std::max<uint64_t>(1, info->decoded_bytes))};
  for (double frac : fracs) {
    vox::OpenOptions oo;
    oo.cache_bytes = std::max<size_t>(1, size_t(double(info->decoded_bytes) * frac));
    auto store = vox::Store::Open(dir, oo);
    if (!store.ok()) return Fail(store.status().ToString());
    auto tracer = vox::Tracer<>::Create((*store)->view(), info->meta.brick_level);
    if (!tracer.ok()) return Fail(tracer.status().ToString());
    std::atomic<uint64_t> hits{0};
    std::atomic<bool> failed{false};
    const uint64_t rss_before = RssAnon();
    RssSampler sampler;
    const vox::Stopwatch t1;
    const glm::dvec3 eye(c * 0.8, c * 1.1, -1.2 * n);
    tbb::parallel_for(0, H, [&](int y) {
      for (int x = 0; x < W; ++x) {
        glm::dvec3 target(n * (x + 0.5) / W, n * (y + 0.5) / H, c);
        auto h = tracer->FirstHit(vox::Ray{eye, target - eye});
        if (!h.ok()) { failed = true; continue; }
        if (h->has_value()) {
          ++hits;
          if (!(*store)->Attributes((*h)->brick, (*h)->payload).ok()) failed = true;
        }
      }
    });
    double s = t1.Seconds();
    if (failed) return Fail("tracing failed");
    vox::CacheStats cs = (*store)->cache_stats();
    std::printf("trace 512^2 (cache %.1f%% of bricks = %s): %.2f M rays/s, %llu hits, cache hit "
                "rate %.4f (%llu hits, %llu misses, %llu evictions)\n",
                frac * 100, (std::to_string(oo.cache_bytes >> 10) + " KiB").c_str(),
                W * H / s / 1e6, (unsigned long long)hits.load(),
                double(cs.hits) / double(std::max<uint64_t>(1, cs.hits + cs.misses)),
                (unsigned long long)cs.hits, (unsigned long long)cs.misses,
                (unsigned long long)cs.evictions);
    std::printf("    peak anonymous RSS %.1f MiB (%.1f MiB before tracing; budget %.1f MiB, "
                "resident top %.1f MiB)\n",
                double(sampler.peak()) / (1 << 20), double(rss_before) / (1 << 20),
                double(oo.cache_bytes) / (1 << 20), double((*store)->resident_bytes()) / (1 << 20));
  }
  if (!tmp.empty()) std::filesystem::remove_all(tmp);
  return 0;
}

// vox::IngestArray: a dense array straight into a store, brick by brick
// (array_ingest.h). No OpenVDB grid and no temporary file: the array's
// memory (for a file, its mapping) is read twice, once in memory order for
// the occupied bbox and the active count, then a brick at a time in the
// store's brick order (Morton order of the brick coordinates, which the
// writer and the level-of-detail pyramid take the bricks in). A brick reads
// its 2^B x 2^B rows of 2^B elements; bricks are built in parallel, at most
// two per thread in flight, so the memory held is the writer's and the
// pyramid's, whatever the array's size (a mapped file's pages are the page
// cache's, which the kernel reclaims).
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <random>

#include "core/octree.h"
#include "core/util/parallel.h"
#include "core/util/path_identity.h"
#include "core/util/stopwatch.h"
#include "ingest/array_ingest.h"
#include "ingest/internal/array_values.h"
#include "ingest/internal/resume_key.h"
#include "storage/lod.h"

namespace vox {
namespace {

using ingest_internal::ElementIndex;
using ingest_internal::ElementLoader;

std::string FormatDouble(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

uint64_t NewStoreId() {
  std::random_device rd;
  const uint64_t id = (uint64_t(rd()) << 32) ^ rd() ^
                      uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
  return id != 0 ? id : 1;
}

// Brick coordinates in [0, hi] on each axis in increasing Morton key
// (MortonKey21: x in the lowest bit of each octal digit), without a list:
// a depth-first walk of the octants that meet the range.
class MortonBricks {
 public:
  explicit MortonBricks(const uint64_t hi[3]) {
    int top = 0;
    while ((uint64_t(1) << top) <= std::max({hi[0], hi[1], hi[2]})) ++top;
    for (int a = 0; a < 3; ++a) hi_[a] = hi[a];
    stack_.push_back({0, 0, 0, top});
  }
  bool Next(glm::u64vec3* out) {
    while (!stack_.empty()) {
      const Node n = stack_.back();
      stack_.pop_back();
      if (n.level == 0) {
        *out = glm::u64vec3(n.x, n.y, n.z);
        return true;
      }
      const uint64_t h = uint64_t(1) << (n.level - 1);
      for (int d = 7; d >= 0; --d) {
        const Node c{n.x + (d & 1) * h, n.y + ((d >> 1) & 1) * h, n.z + ((d >> 2) & 1) * h,
                     n.level - 1};
        if (c.x <= hi_[0] && c.y <= hi_[1] && c.z <= hi_[2]) stack_.push_back(c);
      }
    }
    return false;
  }

 private:
  struct Node {
    uint64_t x, y, z;
    int level;
  };
  uint64_t hi_[3];
  std::vector<Node> stack_;
};

class ArrayIngest {
 public:
  ArrayIngest(const ArrayView& a, const ArrayPlacement& place, const IngestOptions& o,
              const WriterFactory& factory, ProgressSink* progress)
      : a_(a), place_(place), o_(o), factory_(factory), progress_(progress) {}

  StatusOr<IngestStats> Run();

 private:
  bool Occupied(float v) const { return v > threshold_; }
  float At(int64_t i, int64_t j, int64_t k) const {
    return load_(a_.data, ElementIndex(a_, i, j, k));
  }
  void Message(const std::string& m) {
    if (progress_) progress_->Message(m);
  }
  bool Cancelled() const { return progress_ && progress_->Cancelled(); }
  Status CheckOptions() const;
  void Scan();
  Status Describe();
  StatusOr<std::unique_ptr<StoreWriter>> CreateWriter();
  LodBuildOptions LodOptions();
  std::vector<BrickVoxel> BrickVoxels(const glm::u64vec3& brick) const;
  bool OccupiedGrid(const glm::u64vec3& g) const;
  Status WriteBricks(StoreWriter* writer);

  const ArrayView& a_;
  const ArrayPlacement& place_;
  const IngestOptions& o_;
  const WriterFactory& factory_;
  ProgressSink* progress_;
  ElementLoader load_ = nullptr;
  float threshold_ = 0;
  IngestStats stats_;
  StoreMeta meta_;
  // The occupied elements' bbox (array indices, inclusive) and count.
  int64_t lo_[3], hi_[3];
  uint64_t active_ = 0;
  int B_ = 0;
  int64_t origin_[3] = {0, 0, 0};  // the store's origin, index coordinates
  std::atomic<bool> lod_cancel_{false};
  std::unique_ptr<LodStream> lod_;
};

Status ArrayIngest::CheckOptions() const {
  if (o_.output.empty()) return InvalidArgumentError("no output store directory given");
  if (o_.zstd_level < 1 || o_.zstd_level > 22)
    return InvalidArgumentError("zstd level " + std::to_string(o_.zstd_level) + " outside 1..22");
  if (o_.normal_bits < 8 || o_.normal_bits > 16)
    return InvalidArgumentError("normal precision " + std::to_string(o_.normal_bits) +
                                " bits outside 8..16");
  if (o_.threads < 0) return InvalidArgumentError("thread count must be >= 0 (0: all cores)");
  const std::string what = o_.input + ": an array";
  if (o_.isovalue)
    return InvalidArgumentError(what +
                                " is a fog volume; --isovalue applies to level sets "
                                "(use --threshold)");
  if (!o_.grid_name.empty() || !o_.color_grid.empty() || !o_.temperature_grid.empty())
    return InvalidArgumentError(what + " has one grid: no --grid, --color or --temperature");
  if (o_.threshold && *o_.threshold != place_.threshold)
    return InvalidArgumentError(what + ": two thresholds given");
  VOX_RETURN_IF_ERROR(ingest_internal::CheckArrayShape(a_.shape, o_.input));
  VOX_RETURN_IF_ERROR(ingest_internal::CheckArrayPlacement(a_, place_, o_.input));
  if (a_.data == nullptr) return InvalidArgumentError(o_.input + ": the array has no data");
  // The store written (and with --force, the one replaced) is never the
  // input nor a directory holding it.
  VOX_RETURN_IF_ERROR(CheckDistinctPaths({{"input", o_.input}}, {{"output store", o_.output}}));
  if (!o_.force && ::access(o_.output.c_str(), F_OK) == 0)
    return InvalidArgumentError(o_.output + ": already exists; pass --force to replace it");
  return OkStatus();
}

// The occupied bbox and count, in memory order (a file is read front to
// back), an outer slab per task.
void ArrayIngest::Scan() {
  const int64_t n[3] = {a_.shape[0], a_.shape[1], a_.shape[2]};
  const int outer = a_.fortran_order ? 2 : 0;  // the slowest axis in memory
  std::mutex mu;
  for (int a = 0; a < 3; ++a) {
    lo_[a] = std::numeric_limits<int64_t>::max();
    hi_[a] = -1;
  }
  ParallelFor(0, size_t(n[outer]), 1, [&](size_t b, size_t e) {
    int64_t lo[3], hi[3];
    uint64_t count = 0;
    for (int a = 0; a < 3; ++a) lo[a] = std::numeric_limits<int64_t>::max(), hi[a] = -1;
    for (int64_t s = int64_t(b); s < int64_t(e); ++s)
      for (int64_t j = 0; j < n[1]; ++j) {
        const int64_t inner = a_.fortran_order ? n[0] : n[2];
        for (int64_t t = 0; t < inner; ++t) {
          const int64_t c[3] = {a_.fortran_order ? t : s, j, a_.fortran_order ? s : t};
          if (!Occupied(At(c[0], c[1], c[2]))) continue;
          ++count;
          for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
        }
      }
    std::lock_guard<std::mutex> lock(mu);
    active_ += count;
    for (int a = 0; a < 3; ++a) lo_[a] = std::min(lo_[a], lo[a]), hi_[a] = std::max(hi_[a], hi[a]);
  });
}

// The store's metadata: what the .vdb path writes for the same array.
Status ArrayIngest::Describe() {
  meta_.source_file = o_.source.empty() ? o_.input : o_.source;
  meta_.grid_name = "density";
  meta_.grid_class = GridClass::kFogVolume;
  meta_.isovalue = 0.0;
  meta_.threshold = place_.threshold;
  meta_.has_density = true;
  meta_.index_to_world = glm::dmat4(1.0);
  for (int a = 0; a < 3; ++a) meta_.index_to_world[a][a] = place_.voxel_size;
  meta_.voxel_size = place_.voxel_size;
  meta_.build_options = o_.command_line;
  if (meta_.build_options.empty()) {
    meta_.build_options = "levels=" + o_.levels + " zstd_level=" + std::to_string(o_.zstd_level) +
                          " threshold=" + FormatDouble(place_.threshold);
    if (o_.normal_bits != 16)
      meta_.build_options += " normal_bits=" + std::to_string(o_.normal_bits);
  }
  VOX_ASSIGN_OR_RETURN(LevelsChoice choice, ParseLevels(o_.levels));
  const bool empty = active_ == 0;
  int64_t bmin[3], bmax[3];
  for (int a = 0; a < 3; ++a) {
    bmin[a] = empty ? 0 : lo_[a] + place_.origin[size_t(a)];
    bmax[a] = empty ? -1 : hi_[a] + place_.origin[size_t(a)];
  }
  VOX_ASSIGN_OR_RETURN(Placement pl, PlaceGrid(bmin, bmax, choice));
  meta_.levels = pl.levels;
  meta_.brick_level = pl.brick_level;
  meta_.origin = glm::i64vec3(pl.origin[0], pl.origin[1], pl.origin[2]);
  meta_.bbox_min = glm::i64vec3(bmin[0], bmin[1], bmin[2]);
  meta_.bbox_max = glm::i64vec3(bmax[0], bmax[1], bmax[2]);
  B_ = pl.levels - pl.brick_level;
  for (int a = 0; a < 3; ++a) origin_[a] = pl.origin[a];
  stats_.meta = meta_;
  if (empty) {
    Message("nothing occupied: writing an empty store");
  } else {
    Message("occupied bbox [" + std::to_string(bmin[0]) + "," + std::to_string(bmin[1]) + "," +
            std::to_string(bmin[2]) + "] -> [" + std::to_string(bmax[0]) + "," +
            std::to_string(bmax[1]) + "," + std::to_string(bmax[2]) + "], levels " +
            std::to_string(pl.brick_level) + "+" + std::to_string(B_));
  }
  return OkStatus();
}

LodBuildOptions ArrayIngest::LodOptions() {
  LodBuildOptions lo;
  lo.zstd_level = o_.zstd_level;
  lo.normal_bits = o_.normal_bits;
  lo.threads = o_.threads;
  lo.cancel = &lod_cancel_;
  lo.unfinished_ingest = true;
  lo.progress = [this](uint64_t, uint64_t) {
    if (Cancelled()) lod_cancel_ = true;
  };
  return lo;
}

// The writer, with the pyramid built with the bricks and published with
// the store (as the .vdb path's grid ingest does).
StatusOr<std::unique_ptr<StoreWriter>> ArrayIngest::CreateWriter() {
  WriteOptions wo;
  wo.zstd_level = o_.zstd_level;
  wo.normal_bits = o_.normal_bits;
  wo.force = o_.force;
  wo.resume_key = ingest_internal::ResumeKeyOf(
      o_, "array " + a_.dtype + " " + std::to_string(a_.shape[0]) + "x" +
              std::to_string(a_.shape[1]) + "x" + std::to_string(a_.shape[2]) +
              (a_.fortran_order ? " fortran order" : " C order"));
  if (o_.lod) {
    wo.store_id = NewStoreId();
    wo.before_publish = [this](const std::string& temp_dir) -> Status {
      Stopwatch lod_time;
      if (lod_ == nullptr) Message("building the level-of-detail pyramid");
      lod_cancel_ = Cancelled();
      StatusOr<LodBuildStats> built =
          lod_ ? lod_->Finish(temp_dir) : BuildLod(temp_dir, LodOptions());
      if (lod_cancel_ || Cancelled()) return UnavailableError(o_.input + ": ingest cancelled");
      VOX_ASSIGN_OR_RETURN(LodBuildStats ls, std::move(built));
      stats_.lod_levels = ls.levels;
      stats_.seconds_lod = lod_time.Seconds();
      return OkStatus();
    };
  }
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<StoreWriter> writer, factory_(o_.output, meta_, wo));
  if (!writer->resume_note().empty()) Message(writer->resume_note());
  // Bricks kept from an earlier run are not built again: the pyramid is
  // built from the whole base store before it is published (BuildLod).
  if (o_.lod && !writer->temp_dir().empty() && writer->resumed_bricks() == 0) {
    Message("building the level-of-detail pyramid with the bricks");
    VOX_ASSIGN_OR_RETURN(lod_, LodStream::Create(writer->temp_dir(), meta_, wo, LodOptions()));
  }
  return writer;
}

// The occupied voxels of a brick, in memory order (the writer sorts them).
std::vector<BrickVoxel> ArrayIngest::BrickVoxels(const glm::u64vec3& brick) const {
  const int64_t side = int64_t(1) << B_;
  int64_t lo[3], hi[3], base[3];
  for (int a = 0; a < 3; ++a) {
    base[a] = origin_[a] + (int64_t(brick[a]) << B_) - place_.origin[size_t(a)];
    lo[a] = std::max<int64_t>(base[a], lo_[a]);
    hi[a] = std::min<int64_t>(base[a] + side - 1, hi_[a]);
  }
  std::vector<BrickVoxel> out;
  const auto add = [&](int64_t i, int64_t j, int64_t k) {
    const float v = At(i, j, k);
    if (!Occupied(v)) return;
    BrickVoxel bv;
    bv.x = uint32_t(i - base[0]);
    bv.y = uint32_t(j - base[1]);
    bv.z = uint32_t(k - base[2]);
    bv.attr.density = v;
    out.push_back(bv);
  };
  if (a_.fortran_order) {
    for (int64_t k = lo[2]; k <= hi[2]; ++k)
      for (int64_t j = lo[1]; j <= hi[1]; ++j)
        for (int64_t i = lo[0]; i <= hi[0]; ++i) add(i, j, k);
  } else {
    for (int64_t i = lo[0]; i <= hi[0]; ++i)
      for (int64_t j = lo[1]; j <= hi[1]; ++j)
        for (int64_t k = lo[2]; k <= hi[2]; ++k) add(i, j, k);
  }
  return out;
}

// Whether the store's grid voxel g (from its origin) is occupied.
bool ArrayIngest::OccupiedGrid(const glm::u64vec3& g) const {
  int64_t c[3];
  for (int a = 0; a < 3; ++a) {
    c[a] = origin_[a] + int64_t(g[a]) - place_.origin[size_t(a)];
    if (c[a] < lo_[a] || c[a] > hi_[a]) return false;
  }
  return Occupied(At(c[0], c[1], c[2]));
}

Status ArrayIngest::WriteBricks(StoreWriter* writer) {
  struct Item {
    uint64_t index = 0;
    glm::u64vec3 brick{0};
    size_t voxels = 0;
    std::shared_ptr<LodReducedBrick> lod;
  };
  uint64_t hi[3];
  uint64_t total = 1;
  for (int a = 0; a < 3; ++a) {
    hi[a] = uint64_t((hi_[a] + place_.origin[size_t(a)] - origin_[a]) >> B_);
    total *= hi[a] + 1;
  }
  Message("writing up to " + std::to_string(total) + " bricks of " + std::to_string(1 << B_) +
          "^3 voxels");
  MortonBricks bricks(hi);
  std::atomic<bool> failed{false};
  std::mutex error_mu;
  Status first_error;
  auto fail = [&](Status s) {
    std::lock_guard<std::mutex> lock(error_mu);
    if (first_error.ok()) first_error = std::move(s);
    failed.store(true);
  };
  uint64_t next = 0, written = 0, voxels_done = 0;
  const int threads = DefaultThreads();
  RunPipeline<Item>(
      threads, size_t(std::max(2, 2 * threads)),
      [&](Item& it) {
        if (failed.load() || !bricks.Next(&it.brick)) return false;
        it.index = next++;
        return true;
      },
      [&](Item& it) {
        if (failed.load()) return;
        uint32_t kept = 0;
        if (writer->Resumed(it.brick, &kept)) {
          it.voxels = kept;  // written by an earlier run (resumable writing)
          return;
        }
        try {
          std::vector<BrickVoxel> voxels = BrickVoxels(it.brick);
          it.voxels = voxels.size();
          if (voxels.empty()) return;
          if (lod_) {
            auto r = lod_->Reduce(it.brick, voxels,
                                  [this](const glm::u64vec3& g) { return OccupiedGrid(g); });
            if (!r.ok()) return fail(r.status());
            it.lod = std::move(r).value();
          }
          Status s = writer->AddBrick(it.brick, std::move(voxels));
          if (!s.ok()) fail(s);
        } catch (const std::bad_alloc&) {
          fail(ResourceExhaustedError("out of memory while building brick " +
                                      std::to_string(it.index) + " of " + o_.input));
        }
      },
      [&](Item& it) {
        if (failed.load()) return;
        if (it.lod) {  // in brick order
          Status s = lod_->Take(it.lod);
          it.lod.reset();
          if (!s.ok()) return fail(s);
        }
        voxels_done += it.voxels;
        if (it.voxels) ++written;
        if (progress_) progress_->Progress(it.index + 1, total, voxels_done);
        if (Cancelled()) fail(UnavailableError(o_.input + ": ingest cancelled"));
      });
  if (!first_error.ok()) return first_error;
  stats_.occupied_voxels = voxels_done;
  stats_.bricks = written;
  return OkStatus();
}

StatusOr<IngestStats> ArrayIngest::Run() {
  const Stopwatch t_start;
  VOX_RETURN_IF_ERROR(CheckOptions());
  VOX_ASSIGN_OR_RETURN(std::string code, ingest_internal::CanonicalDtype(a_.dtype));
  load_ = ingest_internal::LoaderOf(code);
  threshold_ = float(place_.threshold);
  stats_.input_bytes = uint64_t(a_.shape[0]) * uint64_t(a_.shape[1]) * uint64_t(a_.shape[2]) *
                       uint64_t(code[1] - '0');
  const int threads = o_.threads > 0 ? o_.threads : DefaultThreads();
  stats_.threads = threads;
  Status s;
  WithThreadLimit(threads, [&] {
    Stopwatch t0;
    if (progress_)
      progress_->Message("reading " + o_.input + " for its occupied bbox (" +
                         std::to_string(a_.shape[0]) + " x " + std::to_string(a_.shape[1]) + " x " +
                         std::to_string(a_.shape[2]) + " " + a_.dtype + ")");
    Scan();
    stats_.active_voxels = active_;
    stats_.seconds_bbox = t0.Seconds();
    if (Cancelled()) {
      s = UnavailableError(o_.input + ": ingest cancelled");
      return;
    }
    s = Describe();
    if (!s.ok()) return;
    auto writer = CreateWriter();
    if (!writer.ok()) {
      s = writer.status();
      return;
    }
    t0.Restart();
    if (active_ > 0) s = WriteBricks(writer->get());
    if (!s.ok()) return;
    stats_.seconds_bricks = t0.Seconds();
    t0.Restart();
    if (Cancelled()) {
      s = UnavailableError(o_.input + ": ingest cancelled");
      return;
    }
    s = (*writer)->Finish();
    stats_.seconds_finish = t0.Seconds();
  });
  if (!s.ok()) return s;
  stats_.seconds_total = t_start.Seconds();
  if (progress_) progress_->Done();
  return stats_;
}

}  // namespace

StatusOr<IngestStats> IngestArrayWithWriter(const ArrayView& array, const ArrayPlacement& placement,
                                            const IngestOptions& options,
                                            const WriterFactory& factory, ProgressSink* progress) {
  try {
    return ArrayIngest(array, placement, options, factory, progress).Run();
  } catch (const std::bad_alloc&) {
    return ResourceExhaustedError("out of memory ingesting " + options.input);
  } catch (const std::exception& e) {
    return InternalError("ingesting " + options.input + ": " + e.what());
  }
}

StatusOr<IngestStats> IngestArray(const ArrayView& array, const ArrayPlacement& placement,
                                  const IngestOptions& options, ProgressSink* progress) {
  return IngestArrayWithWriter(array, placement, options, &StoreWriter::Create, progress);
}

}  // namespace vox

// BuildLod: a streaming pass over the base store's bricks, reduced on
// worker threads and written in brick order by a PyramidWriter.
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include "core/util/file.h"
#include "storage/internal/format.h"
#include "storage/internal/lod_reduce.h"
#include "storage/internal/lod_write.h"
#include "storage/lod.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using storage_internal::Aggregate;
using storage_internal::BaseFormat;
using storage_internal::Cascade;
using storage_internal::kLodDirName;
using storage_internal::kLodMaxBitmapDepth;
using storage_internal::LevelFormat;
using storage_internal::PyramidWriter;
using storage_internal::VoxelSums;

// One unit of the base store's walk: a brick (or a voxel of the top pool,
// brick == kNoBrick), with its coordinates at its tree level.
struct BaseJob {
  uint32_t index = 0;         // brick id, or the voxel's payload in the top pool
  uint32_t brick = kNoBrick;  // == index for a brick
  int level = 0;              // tree level of `coord`
  glm::u64vec3 coord{0};
};

// The base store's bricks and top voxels in Morton order (the top alone is read).
void CollectJobs(const OctreeView& view, const CompactCell* pool, uint32_t cell, int level,
                 const glm::u64vec3& coord, std::vector<BaseJob>* jobs) {
  const CompactCell c = pool[cell];
  for (unsigned d = 0; d < 8; ++d) {
    const ChildRef r = ChildOf(c, d, level, view);
    if (r.kind == ChildRef::kEmpty) continue;
    const glm::u64vec3 child =
        (coord << uint64_t(1)) + glm::u64vec3(d & 1u, (d >> 1) & 1u, (d >> 2) & 1u);
    if (r.kind == ChildRef::kCell) {
      CollectJobs(view, pool, r.index, level + 1, child, jobs);
    } else {
      BaseJob j;
      j.index = r.index;
      j.brick = r.kind == ChildRef::kBrick ? r.index : kNoBrick;
      j.level = level + 1;
      j.coord = child;
      jobs->push_back(j);
    }
  }
}

// Reduces one job: walks its voxels in Morton order through a cascade of
// the levels whose cells lie inside one brick. One per thread.
class JobReducer {
 public:
  JobReducer(Store& store, const std::vector<LevelFormat>& local)
      : store_(store), view_(store.view()), local_(local), base_(store.meta()) {}

  // The job's coarse voxels of the local levels, and the cells it hands up.
  using Result = LodReducedBrick;

  void Run(const BaseJob& job, Result* r) {
    Cascade cascade(local_);
    r->status =
        job.brick != kNoBrick ? RunBrick(job, cascade) : Voxel(job, kNoBrick, nullptr, cascade);
    if (!r->status.ok()) return;
    cascade.TakeInto(r);
  }

 private:
  // A brick's voxels are listed first (and marked in an occupancy bitmap
  // when the brick is at most kMaxBitmapDepth levels deep), then reduced:
  // the surface test then looks up its neighbours in the same brick in the
  // bitmap instead of descending the brick's cells.

  Status RunBrick(const BaseJob& job, Cascade& cascade) {
    VOX_ASSIGN_OR_RETURN(BrickView b, store_.FetchBrick(job.brick));
    brick_cells_ = b.cells;
    brick_coord_ = job.coord;
    const int depth = view_.levels - view_.brick_level;
    bitmap_depth_ = depth <= kLodMaxBitmapDepth ? depth : -1;
    if (bitmap_depth_ >= 0)
      occupied_.assign(std::max<size_t>(1, (size_t(1) << (3 * depth)) / 64), 0);
    voxels_.clear();
    Status s = List(b.cells, 0, job.level, job.coord);
    for (size_t i = 0; s.ok() && i < voxels_.size(); ++i)
      s = Voxel(voxels_[i], job.brick, b.data, cascade);
    brick_cells_ = nullptr;
    bitmap_depth_ = -1;
    return s;
  }

  // Lists the voxels under `cell` in Morton order into voxels_, marking occupied_.
  Status List(const CompactCell* pool, uint32_t cell, int level, const glm::u64vec3& coord) {
    const CompactCell c = pool[cell];
    for (unsigned d = 0; d < 8; ++d) {
      const ChildRef r = ChildOf(c, d, level, view_);
      if (r.kind == ChildRef::kEmpty) continue;
      const glm::u64vec3 child = (coord << uint64_t(1)) +
                                 glm::u64vec3(d & 1u, (d >> 1) & 1u, (d >> 2) & 1u);
      if (r.kind == ChildRef::kCell) {
        VOX_RETURN_IF_ERROR(List(pool, r.index, level + 1, child));
      } else if (r.kind == ChildRef::kPayload) {
        BaseJob v;
        v.index = r.index;
        v.level = level + 1;
        v.coord = child;
        voxels_.push_back(v);
        if (bitmap_depth_ >= 0) {
          const size_t bit = BitOf(child);
          occupied_[bit >> 6] |= uint64_t(1) << (bit & 63);
        }
      } else {
        return CorruptionError("a brick inside a brick in the base store's octree");
      }
    }
    return OkStatus();
  }

  // The bit of base voxel `c` (in the brick being walked) in occupied_.
  size_t BitOf(const glm::u64vec3& c) const {
    const uint64_t mask = (uint64_t(1) << bitmap_depth_) - 1;
    return size_t(((c.z & mask) << (2 * bitmap_depth_)) | ((c.y & mask) << bitmap_depth_) |
                  (c.x & mask));
  }

  // One occupied base voxel (payload v.index of `brick`) into the cascade.
  Status Voxel(const BaseJob& v, uint32_t brick, const void* brick_data, Cascade& cascade) {
    Hit h;
    h.brick = brick;
    h.payload = v.index;
    h.brick_data = brick_data;
    VOX_ASSIGN_OR_RETURN(VoxelAttributes a, store_.HitAttributes(h));
    Status error;
    const Aggregate g = VoxelSums(a, v.coord, base_, [&](const glm::i64vec3& out) {
      StatusOr<bool> o = Occupied(out);
      if (!o.ok()) error = o.status();
      return o.ok() && *o;
    });
    VOX_RETURN_IF_ERROR(error);
    cascade.Push(1, v.coord, g);
    return OkStatus();
  }

  // Whether base voxel `v` (grid coordinates) is occupied: from the current
  // brick's cells when it lies in that brick, else down from the top (its
  // brick through the store's cache).
  StatusOr<bool> Occupied(const glm::i64vec3& v) {
    const int64_t n = int64_t(1) << view_.levels;
    if (v.x < 0 || v.y < 0 || v.z < 0 || v.x >= n || v.y >= n || v.z >= n) return false;
    const glm::u64vec3 c(v);
    const int depth = view_.levels - view_.brick_level;
    const bool same_brick = brick_cells_ != nullptr && (c >> uint64_t(depth)) == brick_coord_;
    if (same_brick && bitmap_depth_ >= 0) {
      const size_t bit = BitOf(c);
      return ((occupied_[bit >> 6] >> (bit & 63)) & 1) != 0;
    }
    const CompactCell* pool = same_brick ? brick_cells_ : view_.top;
    int level = same_brick ? view_.brick_level : 0;
    CompactCell cell = pool[0];
    BrickView pin;
    for (; level < view_.levels; ++level) {
      const int bit = view_.levels - 1 - level;
      const unsigned d = unsigned((c.x >> bit) & 1) | unsigned(((c.y >> bit) & 1) << 1) |
                         unsigned(((c.z >> bit) & 1) << 2);
      const ChildRef r = ChildOf(cell, d, level, view_);
      if (r.kind == ChildRef::kEmpty) return false;
      if (r.kind == ChildRef::kPayload) return true;
      if (r.kind == ChildRef::kBrick) {
        VOX_ASSIGN_OR_RETURN(pin, store_.FetchBrick(r.index));
        pool = pin.cells;
        cell = pool[0];
      } else {
        cell = pool[r.index];
      }
    }
    return false;
  }

  Store& store_;
  OctreeView view_;
  const std::vector<LevelFormat>& local_;
  const BaseFormat base_;
  const CompactCell* brick_cells_ = nullptr;  // the brick being walked
  glm::u64vec3 brick_coord_{0};               // its coordinates in the brick grid
  int bitmap_depth_ = -1;                     // occupied_'s side is 2^this; -1: none
  std::vector<uint64_t> occupied_;            // the brick's voxels, x fastest
  std::vector<BaseJob> voxels_;               // the brick's voxels, Morton order
};

// LodBuildOptions::threads, 0 meaning one per core.
int BuildThreads(const LodBuildOptions& o) {
  return o.threads > 0 ? o.threads : int(std::max(1u, std::thread::hardware_concurrency()));
}

// Reduces `jobs` on LodBuildOptions::threads threads (0: one per core; 1:
// on this thread alone) and hands each result to `take` on this thread, in
// job order. Workers run at most a window of jobs ahead of `take`, so memory
// stays bounded; the first error, or the cancel flag, stops the run.
Status RunJobs(Store& base, const std::vector<BaseJob>& jobs,
               const std::vector<LevelFormat>& local, const LodBuildOptions& o,
               const std::function<Status(const BaseJob&, JobReducer::Result&)>& take) {
  constexpr size_t kPrefetchWindow = 8;  // bricks asked for ahead of the walk
  auto cancelled = [&] { return o.cancel != nullptr && o.cancel->load(); };
  const Status interrupted = IoError("interrupted; no level-of-detail pyramid written");
  size_t prefetched_to = 0;
  auto prefetch = [&](size_t i) {  // ahead of job i
    if (i < prefetched_to) return;
    std::vector<uint32_t> ids;
    const size_t end = std::min(jobs.size(), i + kPrefetchWindow);
    for (size_t k = i + 1; k < end; ++k)
      if (jobs[k].brick != kNoBrick) ids.push_back(jobs[k].brick);
    base.Prefetch(ids);
    prefetched_to = end;
  };
  const int threads = BuildThreads(o);
  if (threads <= 1 || jobs.size() < 2) {
    JobReducer reducer(base, local);
    for (const BaseJob& job : jobs) {
      if (cancelled()) return interrupted;
      prefetch(size_t(&job - jobs.data()));
      JobReducer::Result r;
      reducer.Run(job, &r);
      VOX_RETURN_IF_ERROR(r.status);
      VOX_RETURN_IF_ERROR(take(job, r));
    }
    return OkStatus();
  }

  // Reduced bricks waiting for this thread: a few per worker keep them busy
  // (bricks cost about the same), and each holds its coarse voxels (tens of KB).
  const size_t window = 4 * size_t(threads) + 4;
  struct Slot {
    bool ready = false;
    JobReducer::Result result;
  };
  std::vector<Slot> slots(window);
  std::mutex mu;
  std::condition_variable ready_cv, space_cv;
  size_t next = 0, taken = 0;
  bool stop = false;
  auto work = [&] {
    JobReducer reducer(base, local);
    for (;;) {
      size_t i;
      {
        std::unique_lock<std::mutex> lock(mu);
        space_cv.wait(lock, [&] { return stop || next >= jobs.size() || next < taken + window; });
        if (stop || next >= jobs.size()) return;
        i = next++;
        prefetch(i);
      }
      JobReducer::Result r;
      if (cancelled())
        r.status = interrupted;
      else
        reducer.Run(jobs[i], &r);
      std::lock_guard<std::mutex> lock(mu);
      slots[i % window].result = std::move(r);
      slots[i % window].ready = true;
      ready_cv.notify_all();
    }
  };
  std::vector<std::thread> workers;
  struct Join {  // however the run ends
    std::vector<std::thread>& workers;
    std::mutex& mu;
    bool& stop;
    std::condition_variable& cv;
    ~Join() {
      {
        std::lock_guard<std::mutex> lock(mu);
        stop = true;
      }
      cv.notify_all();
      for (std::thread& t : workers) t.join();
    }
  } join{workers, mu, stop, space_cv};
  for (int t = 0; t < threads; ++t) workers.emplace_back(work);
  for (size_t i = 0; i < jobs.size(); ++i) {
    JobReducer::Result r;
    {
      std::unique_lock<std::mutex> lock(mu);
      ready_cv.wait(lock, [&] { return slots[i % window].ready; });
      r = std::move(slots[i % window].result);
      slots[i % window].ready = false;
      taken = i + 1;
    }
    space_cv.notify_all();
    if (cancelled()) return interrupted;
    VOX_RETURN_IF_ERROR(r.status);
    VOX_RETURN_IF_ERROR(take(jobs[i], r));
  }
  return OkStatus();
}

}  // namespace

StatusOr<LodBuildStats> BuildLod(const std::string& store_dir, const LodBuildOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  const fs::path target = fs::path(store_dir) / kLodDirName;
  VOX_ASSIGN_OR_RETURN(const CheckedTarget checked, CheckTarget(target.string()));
  if (checked.exists && !options.force)
    return InvalidArgumentError("'" + target.string() +
                                "' already exists (replace it with --force)");
  OpenOptions oo;
  // Each worker walks a brick and may look into its neighbours.
  oo.cache_bytes = options.cache_bytes * size_t(BuildThreads(options));
  oo.unfinished_ingest = options.unfinished_ingest;
  VOX_ASSIGN_OR_RETURN(auto base, Store::Open(store_dir, oo));
  if (base->meta().lod_level != 0)
    return InvalidArgumentError("'" + store_dir + "' is a level-of-detail store, not a base store");

  VOX_ASSIGN_OR_RETURN(const std::string temp,
                       CreateTemporary(target.string(), /*directory=*/true));
  struct Cleanup {
    std::string dir;
    bool keep = false;
    ~Cleanup() {
      std::error_code e;
      if (!keep) fs::remove_all(dir, e);
    }
  } cleanup{temp};

  LodBuildStats stats;
  {
    // The levels whose cells lie inside one base brick are reduced brick by
    // brick on the worker threads, the rest on this thread (PyramidWriter).
    const StoreMeta& bm = base->meta();
    PyramidWriter pyramid;
    VOX_RETURN_IF_ERROR(pyramid.Init(bm, base->store_id(), temp, options));
    std::vector<BaseJob> jobs;
    const OctreeView view = base->view();
    if (view.top != nullptr && bm.voxel_count > 0)
      CollectJobs(view, view.top, 0, 0, glm::u64vec3(0), &jobs);
    uint64_t bricks_done = 0;
    // Each reduced brick, in brick order, on this thread.
    auto take = [&](const BaseJob& job, JobReducer::Result& r) -> Status {
      VOX_RETURN_IF_ERROR(pyramid.Take(r));
      if (job.brick != kNoBrick) {
        ++bricks_done;
        if (options.progress) options.progress(bricks_done, bm.brick_count);
      }
      return OkStatus();
    };
    VOX_RETURN_IF_ERROR(RunJobs(*base, jobs, pyramid.local(), options, take));
    VOX_RETURN_IF_ERROR(pyramid.Finish(&stats));
    stats.base_bricks_read = bricks_done;
  }
  VOX_RETURN_IF_ERROR(SyncDir(temp));
  VOX_RETURN_IF_ERROR(PublishAtomically(temp, target.string(), "level-of-detail pyramid", checked));
  cleanup.keep = true;
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace vox

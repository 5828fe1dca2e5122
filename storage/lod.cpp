// BuildLod (a streaming pass over the base store's bricks feeding one run
// reducer and one StoreWriter per level) and LodPyramid::Open.
#include "storage/lod.h"

#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include <glm/geometric.hpp>
#include <glm/gtc/packing.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "core/util/file.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/store_writer.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using storage_internal::kLodDirName;

// What a cell needs from its voxels: sums over its occupied base voxels.
// The normal is area-weighted: only surface voxels (level sets: an occupied
// voxel whose neighbour along the dominant axis of its normal, outwards, is
// not occupied) count, each by the area of surface its column holds,
// 1 / max |n_a|. The voxels deeper in the band carry no surface, and their
// normals are the least accurate (their central differences reach past the
// narrow band, where values are clamped). A cell without a surface voxel
// takes the mean of all its voxels' normals.
struct Aggregate {
  uint64_t count = 0;       // occupied base voxels
  glm::dvec3 normal{0.0};   // sum of their unit normals
  glm::dvec3 surface{0.0};  // sum of the surface voxels' normals, area-weighted
  glm::dvec3 color{0.0};    // sum of their colours
  double density = 0.0;     // sum of their densities (1 each without densities)
  void Add(const Aggregate& o) {
    count += o.count;
    normal += o.normal;
    surface += o.surface;
    color += o.color;
    density += o.density;
  }
};

// What a base voxel's sums depend on in its store's format.
struct BaseFormat {
  BaseFormat() = default;
  explicit BaseFormat(const StoreMeta& m)
      : fog(m.grid_class == GridClass::kFogVolume),
        has_density(m.has_density),
        has_normal(m.has_normal) {}
  bool fog = false, has_density = false, has_normal = false;
};

// The sums of one occupied base voxel at grid `coord` whose attributes, as
// the store returns them, are `a`. `occupied(g)` (a bool) tells whether grid
// voxel g, maybe outside the grid, is occupied. BuildLod and LodStream both
// sum their voxels here, so their pyramids agree bit for bit.
template <class OccupiedFn>
inline Aggregate VoxelSums(const VoxelAttributes& a, const glm::u64vec3& coord,
                           const BaseFormat& f, OccupiedFn&& occupied) {
  Aggregate g;
  g.count = 1;
  g.normal = glm::dvec3(a.normal);
  if (f.has_normal) {
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (std::fabs(g.normal[k]) > std::fabs(g.normal[axis])) axis = k;
    const double na = g.normal[axis];
    if (na != 0) {
      glm::i64vec3 out = glm::i64vec3(coord);
      out[axis] += na > 0 ? 1 : -1;
      if (!occupied(out)) g.surface = g.normal / std::fabs(na);
    }
  }
  g.color = glm::dvec3(a.color);
  g.density = f.has_density ? double(a.density) : (f.fog ? 1.0 : 0.0);
  return g;
}

// A level's deterministic store id, from the base's (never 0).
uint64_t LevelStoreId(uint64_t base_id, int level) {
  uint64_t z = base_id + 0x9E3779B97F4A7C15ull * uint64_t(level + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return z != 0 ? z : 1;
}

// The meta of level l's coarse store: the base's, downsampled. Coarse grid
// voxel v covers base grid voxels [v << l, (v + 1) << l); its index
// coordinate is v (origin 0), placed by index_to_world = M * T * S with the
// base map M, S = scale 2^l, T = translate(base origin + 2^(l-1) - 1/2).
StoreMeta CoarseMeta(const StoreMeta& base, uint64_t base_id, int l, int depth) {
  StoreMeta m = base;
  m.levels = base.levels - l;
  m.brick_level = m.levels - depth;
  m.origin = glm::i64vec3(0);
  const double s = std::ldexp(1.0, l);
  const glm::dvec3 shift = glm::dvec3(base.origin) + glm::dvec3(0.5 * s - 0.5);
  m.index_to_world = base.index_to_world * glm::translate(glm::dmat4(1.0), shift) *
                     glm::scale(glm::dmat4(1.0), glm::dvec3(s));
  m.voxel_size = base.voxel_size * s;
  m.has_coverage = true;
  // Fog: the mean density over a cell (a store without densities counts 1 per voxel).
  m.has_density = base.has_density || base.grid_class == GridClass::kFogVolume;
  m.lod_level = l;
  m.lod_base_store_id = base_id;
  m.lod_base_levels = base.levels;
  m.build_options = "level of detail " + std::to_string(l) + " of: " + base.build_options;
  return m;
}

// How one coarse level stores its voxels.
struct LevelFormat {
  int l = 0, depth = 0;  // the level, and its coarse bricks' depth
  bool has_normal = false, has_color = false, has_density = false;
  double cell_voxels = 1;  // base voxels in a cell, 8^l
};

// A coarse voxel made by a Cascade: its coarse brick, and the voxel in it.
struct CoarseVoxel {
  glm::u64vec3 brick{0};
  BrickVoxel voxel;
};

// A cell of level l - 1 handed up to level l with its sums: what a Cascade
// passes on beyond its last level.
struct CellUp {
  int l = 0;
  glm::u64vec3 coord{0};  // in level l - 1's grid
  Aggregate sums;
};

}  // namespace

// A base brick's share of the pyramid: the coarse voxels of the levels whose
// cells lie inside one base brick ("local" levels), and the cells it hands
// up to the coarser ones.
struct LodReducedBrick {
  Status status;
  glm::u64vec3 brick{0};                      // LodStream: its coordinates
  std::vector<std::vector<CoarseVoxel>> out;  // per local level
  std::vector<CellUp> ups;
};

namespace {

// A cascade of run reducers over the consecutive levels `formats` (first ..
// last): cells arrive in Morton order (Push), each level sums a run of them
// into its cell, and a finished cell becomes a coarse voxel (out(l)) and is
// handed up a level (to the next reducer, or to ups() beyond the last).
// Pure arithmetic: the same pushes give the same voxels and sums, bit for
// bit, however the work is split between cascades.
class Cascade {
 public:
  explicit Cascade(std::vector<LevelFormat> formats)
      : formats_(std::move(formats)), cells_(formats_.size()), out_(formats_.size()) {}

  int first() const { return formats_.empty() ? 1 : formats_.front().l; }
  int last() const { return first() + int(formats_.size()) - 1; }

  // A cell (or voxel) of level l - 1 at `coord` (that level's grid), with its sums.
  void Push(int l, const glm::u64vec3& coord, const Aggregate& a) {
    if (l > last()) {
      ups_.push_back(CellUp{l, coord, a});
      return;
    }
    Cell& c = cells_[size_t(l - first())];
    const glm::u64vec3 parent = coord >> uint64_t(1);
    if (c.active && c.coord != parent) Emit(l);
    if (!c.active) {
      c.active = true;
      c.coord = parent;
      c.sums = Aggregate{};
    }
    c.sums.Add(a);
  }

  // Emits every unfinished cell, finest level first (after the last push).
  void Flush() {
    for (int l = first(); l <= last(); ++l)
      if (cells_[size_t(l - first())].active) Emit(l);
  }

  // Room for the voxels of `base_voxels` base voxels of a surface (4^-l per level).
  void Reserve(size_t base_voxels) {
    for (size_t i = 0; i < out_.size(); ++i)
      out_[i].reserve((base_voxels >> (2 * (first() + int(i)))) + 8);
  }

  // Level l's coarse voxels made so far, in Morton order; the caller may take them.
  std::vector<CoarseVoxel>& out(int l) { return out_[size_t(l - first())]; }
  // Cells handed up beyond the last level, in order.
  std::vector<CellUp>& ups() { return ups_; }

 private:
  struct Cell {
    bool active = false;
    glm::u64vec3 coord{0};
    Aggregate sums;
  };

  // The finished cell of level l: its coarse voxel, its sums up a level.
  void Emit(int l) {
    const LevelFormat& f = formats_[size_t(l - first())];
    Cell& c = cells_[size_t(l - first())];
    c.active = false;
    const Aggregate& a = c.sums;
    CoarseVoxel cv;
    cv.brick = c.coord >> uint64_t(f.depth);
    const glm::u64vec3 local = c.coord - (cv.brick << uint64_t(f.depth));
    BrickVoxel& v = cv.voxel;
    v.x = uint32_t(local.x);
    v.y = uint32_t(local.y);
    v.z = uint32_t(local.z);
    const double cell_voxels = f.cell_voxels;
    v.attr.coverage = float(double(a.count) / cell_voxels);
    if (f.has_normal) {
      const glm::dvec3& n = glm::length(a.surface) > 0 ? a.surface : a.normal;
      const double len = glm::length(n);
      v.attr.normal = len > 0 ? glm::vec3(n / len) : glm::vec3(0.0f);
    }
    if (f.has_color) v.attr.color = glm::vec3(a.color / double(a.count));
    if (f.has_density) v.attr.density = float(a.density / cell_voxels);
    out_[size_t(l - first())].push_back(cv);
    Push(l + 1, c.coord, a);
  }

  std::vector<LevelFormat> formats_;
  std::vector<Cell> cells_;
  std::vector<std::vector<CoarseVoxel>> out_;
  std::vector<CellUp> ups_;
};

// The pyramid's writers: one store per level, coarse voxels arriving in
// Morton order, a coarse brick handed to its writer when the next begins.
class LevelWriters {
 public:
  Status Init(const StoreMeta& base, uint64_t base_id, const std::string& dir,
              const std::vector<LevelFormat>& formats, const LodBuildOptions& o) {
    levels_.resize(formats.size());
    for (size_t i = 0; i < formats.size(); ++i) {
      const int l = formats[i].l;
      WriteOptions wo;
      wo.zstd_level = o.zstd_level;
      wo.normal_bits = o.normal_bits;
      wo.store_id = LevelStoreId(base_id, l);
      VOX_ASSIGN_OR_RETURN(levels_[i].writer,
                           StoreWriter::Create(dir + "/" + std::to_string(l),
                                               CoarseMeta(base, base_id, l, formats[i].depth), wo));
    }
    return OkStatus();
  }

  // Appends level l's voxels (taking them), in Morton order.
  Status Add(int l, std::vector<CoarseVoxel>& voxels) {
    Level& lv = levels_[size_t(l - 1)];
    for (CoarseVoxel& cv : voxels) {
      if (lv.brick_active && cv.brick != lv.brick) VOX_RETURN_IF_ERROR(FlushBrick(lv));
      lv.brick_active = true;
      lv.brick = cv.brick;
      lv.voxels.push_back(cv.voxel);
      ++lv.voxel_count;
    }
    voxels.clear();
    return OkStatus();
  }

  Status Finish(LodBuildStats* stats) {
    for (Level& lv : levels_) {
      VOX_RETURN_IF_ERROR(FlushBrick(lv));
      VOX_RETURN_IF_ERROR(lv.writer->Finish());
      stats->voxels.push_back(lv.voxel_count);
      stats->bricks.push_back(lv.brick_count);
    }
    stats->levels = int(levels_.size());
    return OkStatus();
  }

 private:
  struct Level {
    std::unique_ptr<StoreWriter> writer;
    bool brick_active = false;
    glm::u64vec3 brick{0};
    std::vector<BrickVoxel> voxels;
    uint64_t voxel_count = 0, brick_count = 0;
  };

  Status FlushBrick(Level& lv) {
    if (!lv.brick_active || lv.voxels.empty()) return OkStatus();
    ++lv.brick_count;
    Status s = lv.writer->AddBrick(lv.brick, std::move(lv.voxels));
    lv.voxels = {};
    lv.brick_active = false;
    return s;
  }

  std::vector<Level> levels_;
};

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
    cascade.Flush();
    r->out.resize(local_.size());
    for (size_t i = 0; i < local_.size(); ++i) r->out[i] = std::move(cascade.out(local_[i].l));
    r->ups = std::move(cascade.ups());
  }

 private:
  // A brick's voxels are listed first (and marked in an occupancy bitmap
  // when the brick is at most kMaxBitmapDepth levels deep), then reduced:
  // the surface test then looks up its neighbours in the same brick in the
  // bitmap instead of descending the brick's cells.
  static constexpr int kMaxBitmapDepth = 7;

  Status RunBrick(const BaseJob& job, Cascade& cascade) {
    VOX_ASSIGN_OR_RETURN(BrickView b, store_.FetchBrick(job.brick));
    brick_cells_ = b.cells;
    brick_coord_ = job.coord;
    const int depth = view_.levels - view_.brick_level;
    bitmap_depth_ = depth <= kMaxBitmapDepth ? depth : -1;
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

// The ordered half of a pyramid's build: the reduced base bricks, taken in
// brick order, go to the writers (local levels) and through the cascade of
// the coarser levels, whose cells take one or more whole bricks. One thread;
// the writers get their bricks in order, so the pyramid is byte-reproducible
// however many threads reduced the base bricks.
class PyramidWriter {
 public:
  Status Init(const StoreMeta& bm, uint64_t base_id, const std::string& dir,
              const LodBuildOptions& o) {
    // Levels 1 .. D have their cells inside one base brick (local), the coarser ones not.
    const int max_level = LodMaxLevel(bm.levels);
    const int local_levels = std::min(bm.levels - bm.brick_level, max_level);
    std::vector<LevelFormat> all;
    for (int l = 1; l <= max_level; ++l) {
      LevelFormat f;
      f.l = l;
      f.depth = LodBrickDepth(bm.levels, bm.levels - bm.brick_level, l);
      f.cell_voxels = std::ldexp(1.0, 3 * l);
      const StoreMeta m = CoarseMeta(bm, base_id, l, f.depth);
      f.has_normal = m.has_normal;
      f.has_color = m.has_color;
      f.has_density = m.has_density;
      (l <= local_levels ? local_ : upper_).push_back(f);
      all.push_back(f);
    }
    serial_ = Cascade(upper_);
    return writers_.Init(bm, base_id, dir, all, o);
  }

  // The levels reduced brick by brick (LodReducedBrick::out's).
  const std::vector<LevelFormat>& local() const { return local_; }

  // The next base brick (or top voxel) in brick order, reduced.
  Status Take(LodReducedBrick& r) {
    VOX_RETURN_IF_ERROR(r.status);
    for (size_t i = 0; i < local_.size(); ++i)
      VOX_RETURN_IF_ERROR(writers_.Add(local_[i].l, r.out[i]));
    for (const CellUp& up : r.ups) serial_.Push(up.l, up.coord, up.sums);
    return Drain();
  }

  // After the last brick: the coarse levels' last cells, and every level's store.
  Status Finish(LodBuildStats* stats) {
    serial_.Flush();
    VOX_RETURN_IF_ERROR(Drain());
    return writers_.Finish(stats);
  }

 private:
  Status Drain() {
    for (const LevelFormat& f : upper_) VOX_RETURN_IF_ERROR(writers_.Add(f.l, serial_.out(f.l)));
    serial_.ups().clear();  // beyond the coarsest level
    return OkStatus();
  }

  std::vector<LevelFormat> local_, upper_;
  Cascade serial_{{}};
  LevelWriters writers_;
};

}  // namespace

int LodMaxLevel(int base_levels) { return base_levels >= 3 ? base_levels - 2 : 0; }

int LodBrickDepth(int base_levels, int base_brick_depth, int level) {
  const int levels = base_levels - level;
  return std::max(1, std::min(base_brick_depth, levels - 1));
}

bool HasLod(const std::string& store_dir) {
  std::error_code ec;
  return fs::is_directory(fs::path(store_dir) / kLodDirName, ec);
}

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

// LodStream: the producer's bricks reduced as BuildLod's JobReducer reduces
// them from the store (VoxelSums), into a PyramidWriter inside the store's
// temporary directory.
class LodStream::Impl {
 public:
  Impl(const StoreMeta& base, const WriteOptions& base_options, const LodBuildOptions& options)
      : meta_(base),
        store_id_(base_options.store_id),
        normal_bits_(base_options.normal_bits),
        options_(options),
        format_(base),
        flags_(storage_internal::AttrFlags(base)),
        depth_(base.levels - base.brick_level) {}

  ~Impl() {
    pyramid_.reset();  // its writers' temporaries first
    std::error_code ec;
    if (!temp_.empty() && !published_) fs::remove_all(temp_, ec);
  }

  Status Init(const std::string& store_temp_dir) {
    if (store_id_ == 0)
      return InvalidArgumentError("a pyramid built with its store needs the store's id");
    if (meta_.lod_level != 0)
      return InvalidArgumentError("a level-of-detail store has no pyramid of its own");
    target_ = (fs::path(store_temp_dir) / kLodDirName).string();
    VOX_ASSIGN_OR_RETURN(temp_, CreateTemporary(target_, /*directory=*/true));
    pyramid_ = std::make_unique<PyramidWriter>();
    return pyramid_->Init(meta_, store_id_, temp_, options_);
  }

  StatusOr<std::shared_ptr<LodReducedBrick>> Reduce(const glm::u64vec3& brick,
                                                    const std::vector<BrickVoxel>& voxels,
                                                    const Occupied& occupied) const {
    if (voxels.empty()) return InvalidArgumentError("a base brick without voxels");
    const uint64_t side = uint64_t(1) << depth_;
    // The voxels in Morton order, as the store keeps them (they usually
    // come so; brick-local coordinates fit MortonKey21's 21 bits).
    thread_local std::vector<LeafPoint> points;
    thread_local std::vector<uint32_t> order;
    bool sorted = depth_ <= 21;
    uint64_t prev = 0;
    for (size_t i = 0; i < voxels.size(); ++i) {
      const BrickVoxel& v = voxels[i];
      if (v.x >= side || v.y >= side || v.z >= side)
        return InvalidArgumentError("a voxel outside its brick");
      if (!sorted) continue;
      const uint64_t key = MortonKey21(v.x, v.y, v.z);
      sorted = i == 0 || key > prev;
      prev = key;
    }
    order.resize(voxels.size());
    points.clear();
    if (sorted) {
      for (size_t i = 0; i < order.size(); ++i) order[i] = uint32_t(i);
    } else {
      points.resize(voxels.size());
      for (size_t i = 0; i < voxels.size(); ++i)
        points[i] = {voxels[i].x, voxels[i].y, voxels[i].z, NodeRef(i)};
      SortMorton(&points);
      for (size_t i = 0; i < order.size(); ++i) order[i] = uint32_t(points[i].ref);
    }
    // Occupancy inside the brick: a bitmap while it is small, else a search.
    thread_local std::vector<uint64_t> bitmap;
    const bool use_bitmap = depth_ <= kMaxBitmapDepth;
    auto bit_of = [&](const glm::u64vec3& l) {
      return size_t((l.z << (2 * depth_)) | (l.y << depth_) | l.x);
    };
    if (use_bitmap) {
      bitmap.assign(std::max<size_t>(1, (size_t(1) << (3 * depth_)) / 64), 0);
      for (const BrickVoxel& v : voxels) {
        const size_t b = bit_of(glm::u64vec3(v.x, v.y, v.z));
        bitmap[b >> 6] |= uint64_t(1) << (b & 63);
      }
    } else if (sorted) {  // the points, for the search
      points.resize(voxels.size());
      for (size_t i = 0; i < voxels.size(); ++i)
        points[i] = {voxels[i].x, voxels[i].y, voxels[i].z, NodeRef(i)};
    }
    const int64_t n = int64_t(1) << meta_.levels;
    auto occupied_at = [&](const glm::i64vec3& g) -> bool {
      if (g.x < 0 || g.y < 0 || g.z < 0 || g.x >= n || g.y >= n || g.z >= n) return false;
      const glm::u64vec3 c(g);
      if ((c >> uint64_t(depth_)) != brick) return occupied(c);
      const glm::u64vec3 l = c - (brick << uint64_t(depth_));
      if (use_bitmap) {
        const size_t b = bit_of(l);
        return ((bitmap[b >> 6] >> (b & 63)) & 1) != 0;
      }
      return std::binary_search(points.begin(), points.end(), LeafPoint{l.x, l.y, l.z},
                                MortonLess);
    };

    auto r = std::make_shared<LodReducedBrick>();
    r->brick = brick;
    Cascade cascade(pyramid_->local());
    cascade.Reserve(voxels.size());
    const glm::u64vec3 corner = brick << uint64_t(depth_);
    for (const uint32_t i : order) {
      const BrickVoxel& v = voxels[i];
      const glm::u64vec3 coord = corner + glm::u64vec3(v.x, v.y, v.z);
      cascade.Push(1, coord, VoxelSums(Stored(v.attr), coord, format_, occupied_at));
    }
    cascade.Flush();
    const std::vector<LevelFormat>& local = pyramid_->local();
    r->out.resize(local.size());
    for (size_t i = 0; i < local.size(); ++i) r->out[i] = std::move(cascade.out(local[i].l));
    r->ups = std::move(cascade.ups());
    return r;
  }

  Status Take(LodReducedBrick& r) {
    if (options_.cancel != nullptr && options_.cancel->load())
      return IoError("interrupted; no level-of-detail pyramid written");
    const LeafPoint at{r.brick.x, r.brick.y, r.brick.z};
    if (taken_ > 0 && !MortonLess(last_, at))
      return InvalidArgumentError("the pyramid's base bricks came out of brick order");
    last_ = at;
    ++taken_;
    return pyramid_->Take(r);
  }

  StatusOr<LodBuildStats> Finish(const std::string& store_temp_dir) {
    const auto t0 = std::chrono::steady_clock::now();
    if (options_.cancel != nullptr && options_.cancel->load())
      return IoError("interrupted; no level-of-detail pyramid written");
    if ((fs::path(store_temp_dir) / kLodDirName).string() != target_)
      return InvalidArgumentError("the pyramid was begun in another directory");
    // The store it was built with: this one, bricks and all.
    VOX_ASSIGN_OR_RETURN(auto base, Store::Open(store_temp_dir, OpenOptions{}));
    StoreMeta expected = meta_;
    const StoreMeta& got = base->meta();
    expected.voxel_count = got.voxel_count;
    expected.brick_count = got.brick_count;
    expected.top_cells = got.top_cells;
    expected.bbox_min = got.bbox_min;
    expected.bbox_max = got.bbox_max;
    const uint64_t bricks = depth_ == 0 ? got.voxel_count : got.brick_count;
    if (base->store_id() != store_id_ || bricks != taken_ ||
        storage_internal::EncodeMeta(expected) != storage_internal::EncodeMeta(got))
      return InternalError("the level-of-detail pyramid built with store '" + store_temp_dir +
                           "' does not match it");
    base.reset();
    LodBuildStats stats;
    VOX_RETURN_IF_ERROR(pyramid_->Finish(&stats));
    pyramid_.reset();
    stats.base_bricks_read = taken_;
    VOX_RETURN_IF_ERROR(SyncDir(temp_));
    VOX_RETURN_IF_ERROR(PublishAtomically(temp_, target_, "level-of-detail pyramid", {}));
    published_ = true;
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return stats;
  }

 private:
  static constexpr int kMaxBitmapDepth = 7;

  // The attributes the store gives back for `a` (FORMAT.md: quantised
  // normals, half colours; fields it lacks at their defaults).
  VoxelAttributes Stored(const VoxelAttributes& a) const {
    VoxelAttributes s;
    if (flags_ & storage_internal::kAttrNormal)
      s.normal = storage_internal::DecodeOctNormal(
          storage_internal::EncodeOctNormal(a.normal, normal_bits_));
    if (flags_ & storage_internal::kAttrDensity) s.density = a.density;
    if (flags_ & storage_internal::kAttrColor)
      for (int k = 0; k < 3; ++k) s.color[k] = glm::unpackHalf1x16(glm::packHalf1x16(a.color[k]));
    return s;
  }

  const StoreMeta meta_;
  const uint64_t store_id_;
  const int normal_bits_;
  const LodBuildOptions options_;
  const BaseFormat format_;
  const uint8_t flags_;
  const int depth_;
  std::string target_, temp_;  // STORE_TEMP/lod, and the pyramid's temporary beside it
  bool published_ = false;
  std::unique_ptr<PyramidWriter> pyramid_;
  uint64_t taken_ = 0;
  LeafPoint last_;  // the last brick taken
};

StatusOr<std::unique_ptr<LodStream>> LodStream::Create(const std::string& store_temp_dir,
                                                       const StoreMeta& base,
                                                       const WriteOptions& base_options,
                                                       const LodBuildOptions& options) {
  auto impl = std::make_unique<Impl>(base, base_options, options);
  VOX_RETURN_IF_ERROR(impl->Init(store_temp_dir));
  return std::unique_ptr<LodStream>(new LodStream(std::move(impl)));
}

LodStream::LodStream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
LodStream::~LodStream() = default;

StatusOr<std::shared_ptr<LodReducedBrick>> LodStream::Reduce(
    const glm::u64vec3& brick, const std::vector<BrickVoxel>& voxels,
    const Occupied& occupied) const {
  return impl_->Reduce(brick, voxels, occupied);
}

Status LodStream::Take(const std::shared_ptr<LodReducedBrick>& brick) {
  if (brick == nullptr) return InvalidArgumentError("no reduced brick");
  return impl_->Take(*brick);
}

StatusOr<LodBuildStats> LodStream::Finish(const std::string& store_temp_dir) {
  return impl_->Finish(store_temp_dir);
}

StatusOr<std::unique_ptr<LodPyramid>> LodPyramid::Open(const std::string& store_dir, Store& base,
                                                       const OpenOptions& options) {
  const fs::path dir = fs::path(store_dir) / kLodDirName;
  if (!HasLod(store_dir))
    return NotFoundError("store '" + store_dir +
                         "' has no level-of-detail pyramid (lod/): re-ingest it with vox-ingest, "
                         "or add one with `vox-ingest --add-lod " + store_dir + "`");
  const StoreMeta& bm = base.meta();
  auto p = std::unique_ptr<LodPyramid>(new LodPyramid());
  p->base_bricks_ = bm.brick_count;
  for (int l = 1; l <= LodMaxLevel(bm.levels); ++l) {
    const std::string ldir = (dir / std::to_string(l)).string();
    VOX_ASSIGN_OR_RETURN(auto s, Store::Open(ldir, options));
    const StoreMeta& m = s->meta();
    if (m.lod_level != l || m.lod_base_store_id != base.store_id() ||
        m.lod_base_levels != bm.levels)
      return InvalidArgumentError(
          "'" + ldir + "' is not level " + std::to_string(l) + " of store '" + store_dir +
          "' (it belongs to another store: re-build the pyramid with `vox-ingest --add-lod " +
          store_dir + " --force`)");
    if (m.levels != bm.levels - l || m.grid_class != bm.grid_class || !m.has_coverage)
      return InvalidArgumentError("'" + ldir + "' does not fit store '" + store_dir +
                                  "' (levels, grid class or coverage)");
    p->levels_.push_back(std::move(s));
  }
  return p;
}

std::vector<uint64_t> LodPyramid::brick_counts() const {
  std::vector<uint64_t> n{base_bricks_};
  for (const auto& s : levels_) n.push_back(s->meta().brick_count);
  return n;
}

}  // namespace vox

// BuildLod (a streaming pass over the base store's bricks feeding one run
// reducer and one StoreWriter per level) and LodPyramid::Open.
#include "storage/lod.h"

#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <filesystem>

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "storage/file.h"
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

// One level of the cascade: the cell being summed, and the coarse brick
// being filled, handed to the level's writer when the next brick begins.
struct Level {
  int l = 0, depth = 0;
  bool has_normal = false, has_color = false, has_density = false;
  std::unique_ptr<StoreWriter> writer;
  bool cell_active = false;
  glm::u64vec3 cell{0};
  Aggregate agg;
  bool brick_active = false;
  glm::u64vec3 brick{0};
  std::vector<BrickVoxel> voxels;
  uint64_t voxel_count = 0, brick_count = 0;
};

class Cascade {
 public:
  Status Init(const StoreMeta& base, uint64_t base_id, const std::string& dir, int max_level,
              const LodBuildOptions& o) {
    const int base_depth = base.levels - base.brick_level;
    levels_.resize(size_t(max_level));
    for (int l = 1; l <= max_level; ++l) {
      Level& lv = levels_[size_t(l - 1)];
      lv.l = l;
      lv.depth = LodBrickDepth(base.levels, base_depth, l);
      const StoreMeta m = CoarseMeta(base, base_id, l, lv.depth);
      lv.has_normal = m.has_normal;
      lv.has_color = m.has_color;
      lv.has_density = m.has_density;
      WriteOptions wo;
      wo.zstd_level = o.zstd_level;
      wo.normal_bits = o.normal_bits;
      wo.store_id = LevelStoreId(base_id, l);
      VOX_ASSIGN_OR_RETURN(lv.writer,
                           StoreWriter::Create(dir + "/" + std::to_string(l), m, wo));
    }
    return OkStatus();
  }

  // A cell (or voxel) of level l - 1 at `coord` (that level's grid), with its sums.
  Status Push(int l, const glm::u64vec3& coord, const Aggregate& a) {
    if (l > int(levels_.size())) return OkStatus();
    Level& lv = levels_[size_t(l - 1)];
    const glm::u64vec3 parent = coord >> uint64_t(1);
    if (lv.cell_active && lv.cell != parent) VOX_RETURN_IF_ERROR(Emit(lv));
    if (!lv.cell_active) {
      lv.cell_active = true;
      lv.cell = parent;
      lv.agg = Aggregate{};
    }
    lv.agg.Add(a);
    return OkStatus();
  }

  Status Finish(LodBuildStats* stats) {
    for (Level& lv : levels_)
      if (lv.cell_active) VOX_RETURN_IF_ERROR(Emit(lv));
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
  // The finished cell of level lv: its voxel into the coarse brick, its sums up a level.
  Status Emit(Level& lv) {
    lv.cell_active = false;
    const Aggregate& a = lv.agg;
    const glm::u64vec3 brick = lv.cell >> uint64_t(lv.depth);
    if (lv.brick_active && brick != lv.brick) VOX_RETURN_IF_ERROR(FlushBrick(lv));
    lv.brick_active = true;
    lv.brick = brick;
    const double cell_voxels = std::ldexp(1.0, 3 * lv.l);
    BrickVoxel v;
    const glm::u64vec3 local = lv.cell - (brick << uint64_t(lv.depth));
    v.x = uint32_t(local.x);
    v.y = uint32_t(local.y);
    v.z = uint32_t(local.z);
    v.attr.coverage = float(double(a.count) / cell_voxels);
    if (lv.has_normal) {
      const glm::dvec3& n = glm::length(a.surface) > 0 ? a.surface : a.normal;
      const double len = glm::length(n);
      v.attr.normal = len > 0 ? glm::vec3(n / len) : glm::vec3(0.0f);
    }
    if (lv.has_color) v.attr.color = glm::vec3(a.color / double(a.count));
    if (lv.has_density) v.attr.density = float(a.density / cell_voxels);
    lv.voxels.push_back(v);
    ++lv.voxel_count;
    return Push(lv.l + 1, lv.cell, a);
  }

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

// Visits the base store's voxels in Morton order (bricks in id order),
// pushing each into the cascade.
class BaseReader {
 public:
  BaseReader(Store& store, Cascade& cascade, const LodBuildOptions& o)
      : store_(store), cascade_(cascade), o_(o), view_(store.view()) {
    const StoreMeta& m = store.meta();
    fog_ = m.grid_class == GridClass::kFogVolume;
    has_density_ = m.has_density;
    has_normal_ = m.has_normal;
  }

  Status Run(uint64_t* bricks_read) {
    Status s = Walk(view_.top, 0, 0, glm::u64vec3(0), kNoBrick, nullptr);
    *bricks_read = bricks_read_;
    return s;
  }

 private:
  static constexpr uint32_t kPrefetchWindow = 8;

  Status Walk(const CompactCell* pool, uint32_t cell, int level, const glm::u64vec3& coord,
              uint32_t brick, const void* brick_data) {
    const CompactCell c = pool[cell];
    for (unsigned d = 0; d < 8; ++d) {
      const ChildRef r = ChildOf(c, d, level, view_);
      if (r.kind == ChildRef::kEmpty) continue;
      const glm::u64vec3 child = (coord << uint64_t(1)) +
                                 glm::u64vec3(d & 1u, (d >> 1) & 1u, (d >> 2) & 1u);
      if (r.kind == ChildRef::kCell) {
        VOX_RETURN_IF_ERROR(Walk(pool, r.index, level + 1, child, brick, brick_data));
      } else if (r.kind == ChildRef::kBrick) {
        if (o_.cancel != nullptr && o_.cancel->load())
          return IoError("interrupted; no level-of-detail pyramid written");
        brick_coord_ = child;
        if (r.index >= prefetched_to_) {
          std::vector<uint32_t> ids;
          const uint64_t end = std::min<uint64_t>(r.index + kPrefetchWindow, store_.meta().brick_count);
          for (uint64_t i = r.index + 1; i < end; ++i) ids.push_back(uint32_t(i));
          store_.Prefetch(ids);
          prefetched_to_ = uint32_t(end);
        }
        VOX_ASSIGN_OR_RETURN(BrickView b, store_.FetchBrick(r.index));
        brick_cells_ = b.cells;
        const Status walked = Walk(b.cells, 0, level + 1, child, r.index, b.data);
        brick_cells_ = nullptr;
        VOX_RETURN_IF_ERROR(walked);
        ++bricks_read_;
        if (o_.progress) o_.progress(bricks_read_, store_.meta().brick_count);
      } else {
        Hit h;
        h.brick = brick;
        h.payload = r.index;
        h.brick_data = brick_data;
        VOX_ASSIGN_OR_RETURN(VoxelAttributes a, store_.HitAttributes(h));
        Aggregate g;
        g.count = 1;
        g.normal = glm::dvec3(a.normal);
        if (has_normal_) {
          int axis = 0;
          for (int k = 1; k < 3; ++k)
            if (std::fabs(g.normal[k]) > std::fabs(g.normal[axis])) axis = k;
          const double na = g.normal[axis];
          if (na != 0) {
            glm::i64vec3 out = glm::i64vec3(child);
            out[axis] += na > 0 ? 1 : -1;
            VOX_ASSIGN_OR_RETURN(const bool outside_occupied, Occupied(out));
            if (!outside_occupied) g.surface = g.normal / std::fabs(na);
          }
        }
        g.color = glm::dvec3(a.color);
        g.density = has_density_ ? double(a.density) : (fog_ ? 1.0 : 0.0);
        VOX_RETURN_IF_ERROR(cascade_.Push(1, child, g));
      }
    }
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
  Cascade& cascade_;
  const LodBuildOptions& o_;
  OctreeView view_;
  bool fog_ = false, has_density_ = false, has_normal_ = false;
  const CompactCell* brick_cells_ = nullptr;  // the brick being walked
  glm::u64vec3 brick_coord_{0};               // its coordinates in the brick grid
  uint64_t bricks_read_ = 0;
  uint32_t prefetched_to_ = 0;
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
  std::error_code ec;
  const bool exists = fs::exists(fs::symlink_status(target, ec));
  if (exists && !options.force)
    return InvalidArgumentError("'" + target.string() +
                                "' already exists (replace it with --force)");
  OpenOptions oo;
  oo.cache_bytes = options.cache_bytes;
  VOX_ASSIGN_OR_RETURN(auto base, Store::Open(store_dir, oo));
  if (base->meta().lod_level != 0)
    return InvalidArgumentError("'" + store_dir + "' is a level-of-detail store, not a base store");
  const int max_level = LodMaxLevel(base->meta().levels);

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
    Cascade cascade;
    VOX_RETURN_IF_ERROR(cascade.Init(base->meta(), base->store_id(), temp, max_level, options));
    BaseReader reader(*base, cascade, options);
    VOX_RETURN_IF_ERROR(reader.Run(&stats.base_bricks_read));
    VOX_RETURN_IF_ERROR(cascade.Finish(&stats));
  }
  VOX_RETURN_IF_ERROR(SyncDir(temp));
  VOX_RETURN_IF_ERROR(PublishAtomically(temp, target.string(), "level-of-detail pyramid"));
  cleanup.keep = true;
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
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

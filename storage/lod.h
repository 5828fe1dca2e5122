// vox::BuildLod and vox::LodPyramid: the level-of-detail pyramid of a store
// (storage/FORMAT.md, "Level of detail"; docs/lod.md).
//
// The pyramid is a set of coarse stores in `STORE/lod/<l>/` for l = 1 ..
// LodMaxLevel(levels), each an ordinary vox store of the volume downsampled
// by 2^l, so the paper's traversal runs on it unchanged: voxel v of level l
// is the cell of 2^l base voxels per axis at v << l, present when one of
// them is occupied, with the aggregates of that cell as attributes:
//   coverage: the fraction of the cell's 8^l voxels that are occupied;
//   normal:   the area-weighted mean of the surface voxels' normals,
//             renormalised (storage/FORMAT.md);
//   colour:   the mean colour of the occupied voxels;
//   density:  the mean density over the whole cell (empty voxels count 0,
//             a voxel of a fog store without densities counts 1), so a fog's
//             optical depth through the cell is kept.
// Each coarse store names the base store's store_id and levels; a pyramid
// of another store is refused at open.
//
// BuildLod reads the base store once, brick by brick in Morton order (brick
// ids are Morton order, and so are the voxels inside a brick), and feeds a
// cascade of run reducers: a cell's voxels are consecutive in Morton order,
// so each level's voxels come out in Morton order too and each level's
// coarse bricks are consecutive. The levels whose cells lie inside one base
// brick are reduced brick by brick on worker threads; their results are
// taken in brick order, so the pyramid does not depend on the threads.
// Memory: the base store's brick cache, a bounded window of reduced bricks
// and one coarse brick per level, never the volume. LodStream builds the
// same pyramid, byte for byte, from the bricks a producer hands to its
// StoreWriter (vox-ingest, vox-gen), without reading the store again. The pyramid is written into
// a temporary directory and renamed to lod/ at the end, so a failure never
// leaves a partial pyramid that opens.
//
// Thread safety: BuildLod may run on any thread (it reads and writes its
// own stores); a LodPyramid is thread-safe like the Stores it holds.
#ifndef VOX_STORAGE_LOD_H_
#define VOX_STORAGE_LOD_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox {

// The coarsest level a pyramid of a `levels`-level store has: each coarse
// store keeps at least 2 levels (a 4^3 grid). 0: no pyramid (levels < 3).
int LodMaxLevel(int base_levels);

// The brick depth (levels inside a brick) of level l's coarse store: the
// base's brick depth while the grid allows, so coarse bricks hold about as
// many voxels as base bricks.
int LodBrickDepth(int base_levels, int base_brick_depth, int level);

struct LodBuildOptions {
  int zstd_level = 3;
  int normal_bits = 16;
  bool force = false;  // replace an existing lod/ pyramid
  // Decompressed-brick cache for reading the base store: each brick is read
  // once, so it needs only the brick being walked and those prefetched (the
  // build's memory stays flat however large the store).
  size_t cache_bytes = size_t(2) << 20;  // per thread
  // Threads reducing the base bricks (0: one per core). The pyramid is the
  // same, byte for byte, whatever the number.
  int threads = 0;
  // Polled between bricks: when it turns true, the build stops and writes no pyramid.
  const std::atomic<bool>* cancel = nullptr;
  // Called after each base brick (from the calling thread).
  std::function<void(uint64_t bricks_done, uint64_t bricks_total)> progress;
  // The ingest's own build, before it publishes the store: its directory
  // may still hold a resumable ingest's journal (OpenOptions::unfinished_ingest).
  bool unfinished_ingest = false;
};

struct LodBuildStats {
  int levels = 0;                       // coarse levels written (1 .. levels)
  std::vector<uint64_t> voxels, bricks; // per level, index 0 = level 1
  uint64_t base_bricks_read = 0;
  double seconds = 0;
};

// Builds the pyramid of the store at `store_dir` into `store_dir`/lod.
// Refuses an existing lod/ unless options.force.
StatusOr<LodBuildStats> BuildLod(const std::string& store_dir, const LodBuildOptions& options);

// A base brick's share of the pyramid, reduced by LodStream::Reduce.
struct LodReducedBrick;

// Builds the pyramid of a store while its StoreWriter writes it, from the
// voxels its producer hands to the writer (vox-ingest, vox-gen): no second
// pass over the written store. The pyramid is, byte for byte, the one
// BuildLod would write of the finished store. Use:
//  1. Create, once the writer exists, with its temporary directory
//     (StoreWriter::temp_dir), the meta and the options it was made with
//     (options.store_id must be set: the pyramid names it);
//  2. for each brick given to AddBrick, Reduce its voxels (any thread), and
//     Take the reduced bricks on one thread in brick-id (Morton) order;
//  3. Finish from the writer's before_publish: it checks that the store in
//     the directory is the one the bricks made, writes lod/ into it, and
//     the pyramid is published with the store, or not at all.
// Memory: the reduced bricks the caller holds, and one coarse brick per
// level. Without Finish the pyramid's temporaries are removed.
// LodBuildOptions: zstd_level, normal_bits (the coarse stores'), cancel
// (polled by Take and Finish); threads, cache_bytes and progress unused.
//
// Thread safety: Reduce may run on many threads at once; Take and Finish on
// one thread at a time.
class LodStream {
 public:
  // Whether base grid voxel `g` (outside the brick being reduced, inside
  // the grid) is an occupied voxel of the store.
  using Occupied = std::function<bool(const glm::u64vec3& g)>;

  static StatusOr<std::unique_ptr<LodStream>> Create(const std::string& store_temp_dir,
                                                     const StoreMeta& base,
                                                     const WriteOptions& base_options,
                                                     const LodBuildOptions& options);
  ~LodStream();

  // Reduces the brick of the brick grid at `brick` whose voxels (as given
  // to StoreWriter::AddBrick, any order) are `voxels`; `occupied` answers
  // for the voxels beside it (level sets' surface test).
  StatusOr<std::shared_ptr<LodReducedBrick>> Reduce(const glm::u64vec3& brick,
                                                    const std::vector<BrickVoxel>& voxels,
                                                    const Occupied& occupied) const;
  // The next brick in brick-id order (InvalidArgument out of order).
  Status Take(const std::shared_ptr<LodReducedBrick>& brick);
  // Writes `store_temp_dir`/lod (the directory given to Create).
  StatusOr<LodBuildStats> Finish(const std::string& store_temp_dir);

 private:
  class Impl;
  explicit LodStream(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Whether `store_dir` has a lod/ directory (not whether it opens).
bool HasLod(const std::string& store_dir);

// The coarse stores of a base store, opened and checked against it.
class LodPyramid {
 public:
  // Opens `store_dir`/lod/1 .. with `options` each. NotFound when there is
  // no pyramid (the message says to re-ingest or add one with
  // `vox-ingest --add-lod`); InvalidArgument when a level belongs to another
  // store or does not fit the base (levels, grid class).
  static StatusOr<std::unique_ptr<LodPyramid>> Open(const std::string& store_dir,
                                                    Store& base, const OpenOptions& options);
  int max_level() const { return int(levels_.size()); }
  // Level l's store, 1 <= l <= max_level().
  Store* level(int l) const { return levels_[size_t(l - 1)].get(); }
  // Bricks per level (index 0: the base store), for estimates.
  std::vector<uint64_t> brick_counts() const;

 private:
  uint64_t base_bricks_ = 0;
  std::vector<std::unique_ptr<Store>> levels_;
};

}  // namespace vox

#endif  // VOX_STORAGE_LOD_H_

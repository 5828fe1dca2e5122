// The pyramid's writers (storage/lod.h): one StoreWriter per coarse level,
// fed in brick order from the reduced base bricks. BuildLod and LodStream
// both write through a PyramidWriter.
#ifndef VOX_STORAGE_INTERNAL_LOD_WRITE_H_
#define VOX_STORAGE_INTERNAL_LOD_WRITE_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "storage/internal/lod_reduce.h"
#include "storage/lod.h"
#include "storage/store_writer.h"

namespace vox {
namespace storage_internal {

// A level's deterministic store id, from the base's (never 0).
uint64_t LevelStoreId(uint64_t base_id, int level);

// The meta of level l's coarse store: the base's, downsampled. Coarse grid
// voxel v covers base grid voxels [v << l, (v + 1) << l); its index
// coordinate is v (origin 0), placed by index_to_world = M * T * S with the
// base map M, S = scale 2^l, T = translate(base origin + 2^(l-1) - 1/2).
StoreMeta CoarseMeta(const StoreMeta& base, uint64_t base_id, int l, int depth);

// One store per level, coarse voxels arriving in Morton order, a coarse
// brick handed to its writer when the next begins.
class LevelWriters {
 public:
  Status Init(const StoreMeta& base, uint64_t base_id, const std::string& dir,
              const std::vector<LevelFormat>& formats, const LodBuildOptions& o);
  // Appends level l's voxels (taking them), in Morton order.
  Status Add(int l, std::vector<CoarseVoxel>& voxels);
  Status Finish(LodBuildStats* stats);

 private:
  struct Level {
    std::unique_ptr<StoreWriter> writer;
    bool brick_active = false;
    glm::u64vec3 brick{0};
    std::vector<BrickVoxel> voxels;
    uint64_t voxel_count = 0, brick_count = 0;
  };
  Status FlushBrick(Level& lv);

  std::vector<Level> levels_;
};

// The ordered half of a pyramid's build: the reduced base bricks, taken in
// brick order, go to the writers (local levels) and through the cascade of
// the coarser levels, whose cells take one or more whole bricks. One thread;
// the writers get their bricks in order, so the pyramid is byte-reproducible
// however many threads reduced the base bricks.
class PyramidWriter {
 public:
  // Creates the level stores in `dir`/1 .. of the base store `bm` (id `base_id`).
  Status Init(const StoreMeta& bm, uint64_t base_id, const std::string& dir,
              const LodBuildOptions& o);
  // The levels reduced brick by brick (LodReducedBrick::out's).
  const std::vector<LevelFormat>& local() const { return local_; }
  // The next base brick (or top voxel) in brick order, reduced.
  Status Take(LodReducedBrick& r);
  // After the last brick: the coarse levels' last cells, and every level's store.
  Status Finish(LodBuildStats* stats);

 private:
  Status Drain();

  std::vector<LevelFormat> local_, upper_;
  Cascade serial_{{}};
  LevelWriters writers_;
};

}  // namespace storage_internal
}  // namespace vox

#endif  // VOX_STORAGE_INTERNAL_LOD_WRITE_H_

// vox::Volume: what every reader of a voxel volume sees: the octree to
// trace, each voxel's attributes, the placement in world space (meta()) and
// the brick cache's counters (CacheStats). Store (storage/store.h) is the
// disk-backed Volume; render/grid_transform.h's MemoryVolume is an in-memory
// one for tests and demos.
//
// Thread safety: Volume implementations are thread-safe (Attributes and the
// BrickSource behind view() are called from many render threads).
#ifndef VOX_STORAGE_VOLUME_H_
#define VOX_STORAGE_VOLUME_H_

#include <cstdint>
#include <string>

#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"
#include "storage/meta.h"

namespace vox {

struct CacheStats {
  uint64_t hits = 0, misses = 0, evictions = 0;
  uint64_t brick_file_bytes = 0;    // size of the brick file (read with pread)
  uint64_t bytes_decompressed = 0;  // total decompressed since open
  uint64_t bytes_resident = 0;      // decompressed bytes held now
  uint64_t capacity = 0;
  // Prefetch (Store::Prefetch): bricks decoded ahead and cached, those later
  // fetched from the cache, requests dropped (queue full, cancelled, budget
  // tight) and failed (the brick's own fetch reads it again and reports).
  uint64_t prefetched = 0, prefetch_hits = 0, prefetch_dropped = 0, prefetch_failed = 0;
  uint64_t bytes_read = 0;          // brick file bytes vox's reads asked for since open
  uint64_t process_read_bytes = 0;  // the process's bytes read from storage (ProcessIoBytes)
  uint64_t windows_read = 0;        // record windows read (OpenOptions::read_windows)
  uint64_t window_bytes = 0;        // their size now (0: records read alone)
  // Brick table pages read from the index file since open (a table read
  // whole at open counts its pages too), and their bytes.
  uint64_t table_pages_read = 0, table_bytes_read = 0;
  // Brick cache capacity given up to the heap's growth (HeapWatch).
  uint64_t given_to_heap = 0;
};

class Volume {
 public:
  virtual ~Volume() = default;
  virtual const StoreMeta& meta() const = 0;
  // The octree to trace; valid as long as the volume.
  virtual OctreeView view() = 0;
  // Attributes of a voxel hit in brick `brick` (kNoBrick: the top) at `payload`.
  virtual StatusOr<VoxelAttributes> Attributes(uint32_t brick, uint32_t payload) = 0;
  // The same for a hit a traversal of this volume's view() reports. Call it
  // while the hit's brick is pinned (from the traversal's visitor): a volume
  // may read it from the brick (Hit::brick_data: no cache look-up).
  virtual StatusOr<VoxelAttributes> HitAttributes(const Hit& hit) {
    return Attributes(hit.brick, hit.payload);
  }
  // HitAttributes(hit).density read straight from the hit's pinned brick,
  // for fog's inner loop; false when this volume cannot (then ask
  // HitAttributes, which also gives the error). *uniform_levels: the levels
  // of the largest aligned block of 2^levels voxels a side around the hit,
  // within its brick, whose voxels are all occupied and of this density;
  // -1 when there is none (of at least 2^3 voxels).
  virtual bool PinnedDensity(const Hit& /*hit*/, float* /*density*/, int* /*uniform_levels*/) {
    return false;
  }
  // Brick cache counters (zero for volumes without a cache).
  virtual CacheStats cache_stats() const { return {}; }
  // Where the volume comes from, for EXR headers ("memory", a store path).
  virtual std::string description() const = 0;
};

}  // namespace vox

#endif  // VOX_STORAGE_VOLUME_H_

// vox::Volume, vox::Store and vox::StoreWriter. A Volume is what every
// reader of a voxel volume sees: the octree to trace, each voxel's attributes,
// the placement in world space and the brick cache's counters. Store is the
// disk-backed Volume that vox-ingest writes and every reader opens (an
// in-memory one for tests and demos is render/volume.h's MemoryVolume). The
// resident top (levels above the brick level) is loaded at open; each brick
// (the subtree under one occupied octant of the brick level, with its voxels'
// attributes) is a zstd frame in bricks.vxb, read with pread (its own bytes,
// read-ahead off) and decompressed on demand into a byte-budgeted cache, or
// ahead of need by Prefetch on I/O threads.
// The format is specified in storage/FORMAT.md.
//
// Coordinates: grid coordinates g in [0, 2^levels)^3 are what the octree and
// the tracer see. OpenVDB index coordinates are ijk = g + origin. World
// placement is OpenVDB's: voxel ijk covers index_to_world([ijk - 0.5,
// ijk + 0.5)^3). The probe's index space is VDB's shifted by one half (voxel
// ijk is [ijk, ijk + 1)^3), so a probe point P is the grid point P - origin.
//
// Thread safety: Volume implementations are thread-safe (Attributes and the
// BrickSource behind view() are called from many render threads); a Store is
// thread-safe (FetchBrick, Attributes, stats).
// StoreWriter::AddBrick may be called from several threads at once (bricks
// are encoded and compressed in parallel, appended in turn); Finish must not
// race with AddBrick.
#ifndef VOX_STORAGE_STORE_H_
#define VOX_STORAGE_STORE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "core/octree.h"
#include "core/ray.h"
#include "core/status.h"

namespace vox {

enum class GridClass : uint8_t { kLevelSet = 1, kFogVolume = 2 };

struct StoreMeta {
  std::string source_file;   // as given to vox-ingest
  std::string grid_name;
  GridClass grid_class = GridClass::kLevelSet;
  int levels = 0;            // N: the octree covers [0, 2^N)^3 grid voxels
  int brick_level = 0;       // levels above it are resident; a brick holds levels - brick_level
  glm::i64vec3 origin{0};    // VDB index coordinate of grid voxel (0,0,0)
  glm::i64vec3 bbox_min{0};  // VDB index bounds of the occupied voxels, inclusive
  glm::i64vec3 bbox_max{-1};
  glm::dmat4 index_to_world{1.0};  // OpenVDB's linear affine map (GLM column-major: world = M * (ijk, 1))
  double voxel_size = 1.0;         // uniform voxel size (max axis of the map's scale)
  uint64_t voxel_count = 0;        // occupied voxels
  uint64_t brick_count = 0;
  uint64_t top_cells = 0;
  bool has_normal = false;   // level sets: a quantised normal per voxel
  bool has_density = false;  // fog volumes: the density per voxel
  bool has_color = false;    // an RGB colour per voxel (from a vec3 grid)
  bool has_coverage = false; // level-of-detail stores: the fraction of a cell's voxels occupied
  double isovalue = 0.0;     // level sets: occupied when active and value <= isovalue
  double threshold = 0.0;    // fog volumes: occupied when active and density > threshold
  std::string build_options; // the ingest command's options, for the record
  // Level of detail (format 1.1, storage/lod.h): a coarse store of a
  // pyramid is the base store downsampled by 2^lod_level; it names the base
  // store's store_id and levels. 0 / 0 / 0 in a base store.
  int lod_level = 0;
  uint64_t lod_base_store_id = 0;
  int lod_base_levels = 0;
};

// What a brick keeps per occupied voxel. Fields the store does not have are
// zero (normal), 1 (density), 1,1,1 (colour) or 1 (coverage).
struct VoxelAttributes {
  glm::vec3 normal{0.0f};    // unit, in index space (the gradient of the distance field)
  float density = 1.0f;
  glm::vec3 color{1.0f};
  float coverage = 1.0f;     // level-of-detail cells: fraction of their voxels occupied
};

// One occupied voxel handed to the writer, in brick-local coordinates
// (each < 2^(levels - brick_level)).
struct BrickVoxel {
  uint32_t x = 0, y = 0, z = 0;
  VoxelAttributes attr;
};

struct WriteOptions {
  int zstd_level = 3;
  bool force = false;  // replace an existing store at the target
  // Precision of each octahedral normal component, 8..16 bits. Readers need
  // not know: values stay 16-bit, multiples of 2^(16 - bits). 12 bits (max
  // error 0.06 degrees; 16 bits: 0.004) makes level-set stores about a third smaller.
  int normal_bits = 16;
  // The id both files carry (FORMAT.md); 0: random. A fixed id (with bricks
  // added in a fixed order, one at a time) makes the store byte-reproducible.
  uint64_t store_id = 0;
  // Called by Finish with the temporary directory once the store in it is
  // complete and synced, before it is renamed into place: what it adds to
  // the directory (e.g. the level-of-detail pyramid, storage/lod.h) is
  // published with the store, and an error leaves no store at the target.
  std::function<Status(const std::string& temp_dir)> before_publish;
};

class StoreWriter {
 public:
  // Prepares a store at `dir`: builds in a temporary directory beside it,
  // which Finish() fsyncs and renames into place. Refuses an existing target
  // unless options.force. `meta` gives everything but the counts, which the
  // writer fills in.
  static StatusOr<std::unique_ptr<StoreWriter>> Create(const std::string& dir,
                                                       const StoreMeta& meta,
                                                       const WriteOptions& options);
  virtual ~StoreWriter() = default;  // without Finish(): removes the temporary directory
  // Adds the brick of the brick-level octant `brick_coord` (grid coordinates
  // >> (levels - brick_level)). Bricks come in any order, each octant once,
  // each with at least one voxel; voxels in any order, no duplicates.
  virtual Status AddBrick(const glm::u64vec3& brick_coord, std::vector<BrickVoxel> voxels) = 0;
  // Writes the top and the index, fsyncs and renames into place.
  virtual Status Finish() = 0;
};

struct OpenOptions {
  size_t cache_bytes = size_t(256) << 20;  // decompressed-brick budget
  bool verify_checksums = true;
  // Threads reading for Prefetch: each has one read in flight, so this is
  // the queue depth prefetching keeps on the disk (small reads of a brick's
  // own bytes are latency-bound: several at once overlap their waits).
  int io_threads = kDefaultIoThreads;
  static constexpr int kDefaultIoThreads = 8;
  // Read records a window of file neighbours at a time (RecordWindows: one
  // read serves the bricks next in space), keeping the compressed windows in
  // a share of cache_bytes; off: each miss reads its record alone.
  bool read_windows = true;
};
inline constexpr int kMaxIoThreads = 256;

struct CacheStats {
  uint64_t hits = 0, misses = 0, evictions = 0;
  uint64_t bytes_mapped = 0;        // size of the mapped brick file
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
  // Brick cache counters (zero for volumes without a cache).
  virtual CacheStats cache_stats() const { return {}; }
  // Where the volume comes from, for EXR headers ("memory", a store path).
  virtual std::string description() const = 0;
};

// A Volume read from a store directory; its own bricks' BrickSource.
class Store : public Volume, public BrickSource {
 public:
  static StatusOr<std::unique_ptr<Store>> Open(const std::string& dir, const OpenOptions& options);
  ~Store() override = default;

  // Asks for bricks to be read and decoded ahead of their FetchBrick, in the
  // background: returns at once. The requested bricks not yet cached are
  // grouped into runs of neighbours in the brick file (bricks lie in Morton
  // order; a run reads at most 1.5x its bricks' own bytes, plus a page) and
  // read by OpenOptions::io_threads threads, several runs in flight at once,
  // then decoded and cached, so later fetches hit. A fetch of a brick whose
  // run is being read waits for it instead of reading it again; a brick not
  // started yet is read by its fetch as usual. Prefetching stays within the
  // cache budget: prefetched bricks not yet fetched use at most half of it,
  // and requests past that (or past a bounded queue, oldest first) are
  // dropped. A brick whose prefetch fails is not cached: its fetch reads it
  // again and reports the error. Unknown ids are ignored.
  virtual void Prefetch(std::span<const uint32_t> brick_ids) = 0;
  // Decoded bytes of bricks queued for prefetching but not read yet, plus
  // those prefetched and not fetched yet: how far prefetching is ahead.
  virtual uint64_t PrefetchBacklog() const = 0;
  // Drops the requests not yet started (one in progress finishes).
  virtual void CancelPrefetch() = 0;
  // Bytes held in memory for the life of the Store: top cells, top payloads
  // and the brick table (not the cache).
  virtual uint64_t resident_bytes() const = 0;
  // The store_id of the index header and footer (FORMAT.md): random per
  // ingest, so a store re-ingested at the same path has a different one.
  virtual uint64_t store_id() const = 0;
  // Brick sizes from the brick table, for sizing caches and pins.
  struct BrickSizes {
    uint64_t max_decoded = 0;   // the largest brick as the cache holds it (its charge)
    uint64_t mean_decoded = 0;
    uint64_t max_stored = 0;    // the largest brick record on disk
  };
  virtual BrickSizes brick_sizes() const = 0;
  // Changes the brick cache's budget (OpenOptions::cache_bytes), evicting
  // down to it; the cache keeps the number of shards chosen at open. For
  // sizing the cache from a memory budget once resident_bytes() is known.
  virtual void SetCacheCapacity(uint64_t bytes) = 0;
};

}  // namespace vox

#endif  // VOX_STORAGE_STORE_H_

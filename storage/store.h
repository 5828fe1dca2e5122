// vox::Store: the disk-backed Volume (storage/volume.h) that vox-ingest
// writes (storage/store_writer.h) and every reader opens. The resident top
// (levels above the brick level) is loaded at open; each brick (the subtree
// under one occupied octant of the brick level, with its voxels' attributes)
// is a zstd frame in bricks.vxb, read with pread (its own bytes, read-ahead
// off) and decompressed on demand into a byte-budgeted cache, or ahead of
// need by Prefetch on I/O threads. The format is specified in
// storage/FORMAT.md; coordinates are storage/meta.h's.
//
// Thread safety: a Store is thread-safe (FetchBrick, Attributes, stats).
#ifndef VOX_STORAGE_STORE_H_
#define VOX_STORAGE_STORE_H_

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/octree.h"
#include "core/util/status.h"
#include "storage/meta.h"
#include "storage/volume.h"

namespace vox {

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
  // A brick table of at most this many bytes (56 per brick: 75,000 bricks)
  // is read and checked whole at open; a larger one a page of rows at a time
  // when first used (storage/internal/table_pages.h), so that opening a
  // store does not cost its brick count.
  uint64_t whole_table_bytes = uint64_t(4) << 20;
  // The memory budget of the process (0: unchecked): a store whose index
  // would take more than this to read and hold at open is refused before it
  // is read (ResourceExhausted, saying how much it needs), instead of the
  // process being killed by its memory limit.
  uint64_t budget_bytes = 0;
  // A directory holding a resumable ingest's journal is an unfinished
  // ingest and refused; the ingest itself opens it to build the pyramid.
  bool unfinished_ingest = false;
};
inline constexpr int kMaxIoThreads = 256;

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

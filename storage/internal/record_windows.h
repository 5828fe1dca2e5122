// vox::storage_internal::RecordWindows: reads brick records a window at a
// time. A window is every record whose offset starts in one aligned span of
// the brick file (64 KiB to 1 MiB); the first miss on any of them reads the
// window with one pread, and the compressed bytes stay in a cache of their
// own, so the records of the neighbouring bricks (writers append bricks in
// Morton order: close in space, close in the file) cost no further read.
// The records of a window are found from the asking brick's table row
// outwards, over ids whose records follow each other in the file (the
// writers' order; TablePages pages the rows in), so no table-wide order is
// held. In a store written in another order, a window holds fewer records
// and the others are read alone: slower, never wrong.
// Reads cost about the bytes the bricks need (see SetCapacity) in a few
// thousand reads instead of one per brick (110,286 for a full view of the
// 8192^3 sphere).
//
// Thread safety: Read, counters and bytes are thread-safe; SetCapacity must
// not run concurrently with Read.
#ifndef VOX_STORAGE_INTERNAL_RECORD_WINDOWS_H_
#define VOX_STORAGE_INTERNAL_RECORD_WINDOWS_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/util/status.h"
#include "core/util/file.h"
#include "storage/internal/format.h"
#include "storage/internal/table_pages.h"
#include "core/util/memory_budget.h"
#include "storage/page_cache.h"

namespace vox::storage_internal {

class RecordWindows {
 public:
  // `file` and `table` must outlive this object.
  RecordWindows(const RandomAccessFile* file, TablePages* table);

  // The memory the window cache may hold. The window size is the largest
  // power of two of at most 1/128 of it, at most kMaxWindow; below kMinWindow
  // (a cache under 8 MiB) windows are off and every record is read alone.
  // 128 windows in the cache: fewer are evicted before their neighbours are
  // asked for (the replayed reads that chose it: docs/performance.md).
  void SetCapacity(uint64_t bytes);
  uint64_t capacity() const { return capacity_; }
  uint64_t window_bytes() const { return window_; }

  // The share of a brick cache of `cache_bytes` that goes to windows: 1/8,
  // at most kMaxCapacity.
  static uint64_t ShareOf(uint64_t cache_bytes);

  static constexpr uint64_t kMinWindow = uint64_t(64) << 10;
  static constexpr uint64_t kMaxWindow = kMaxReadWindowBytes;
  static constexpr uint64_t kMaxCapacity = uint64_t(64) << 20;

  // Brick `id`'s record (stored_size + kTrailerSize bytes), valid while the
  // returned holder lives. Reads its window unless cached; a window that
  // cannot be read (a file that shrank, an I/O error) falls back to reading
  // the record alone, whose error names the brick. `scratch` holds a record
  // read alone.
  struct Record {
    std::shared_ptr<const void> hold;
    const uint8_t* data = nullptr;
  };
  // `e` is brick `id`'s table row.
  StatusOr<Record> Read(uint32_t id, const BrickEntry& e, std::vector<uint8_t>* scratch);

  // Drops the window of the brick whose row is `e` from the cache (its
  // record failed its checksum: a later read goes to the file again, as a
  // lone record's does).
  void Forget(const BrickEntry& e);

  // Bytes read from the file since construction, and windows read.
  uint64_t bytes_read() const { return bytes_read_.load(std::memory_order_relaxed); }
  uint64_t windows_read() const { return windows_read_.load(std::memory_order_relaxed); }
  // Bytes the window cache holds now.
  uint64_t charge() const { return cache_ ? cache_->TotalCharge() : 0; }

 private:
  struct Window {
    uint64_t begin = 0;
    std::vector<uint8_t> bytes;
  };
  StatusOr<std::shared_ptr<const Window>> LoadWindow(uint64_t w, uint64_t size, uint32_t id,
                                                     const BrickEntry& e);
  Status ReadAlone(uint32_t id, const BrickEntry& e, std::vector<uint8_t>* scratch);

  const RandomAccessFile* file_;
  TablePages* table_;
  uint64_t capacity_ = 0, window_ = 0;
  std::unique_ptr<ShardedPageCache<Window>> cache_;
  std::atomic<uint64_t> bytes_read_{0}, windows_read_{0};
};

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_RECORD_WINDOWS_H_

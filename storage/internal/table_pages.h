// vox::storage_internal::TablePages: a store's brick table, read whole at
// open when it is small, otherwise a page of rows at a time when a brick of
// the page is first asked for, the pages kept in a bounded cache. So opening
// a store costs its metadata and its resident top, not its brick count: the
// 32768^3 sphere has 4.5 M bricks, 250 MB of rows, more than a 512 MiB job
// holds beside its brick cache and 1.7 s of this machine's disk at every open
// (docs/scale.md).
//
// Checks. A page is checked when read: against its CRC from the 1.2
// metadata (TableSummary), then each row as a whole table always was (its
// record inside the brick file, sizes consistent, coordinates inside the
// brick grid), so a bad row is reported, naming the index file, before any
// brick of its page is read. A table read whole is checked at open (the
// block's CRC, every row, the bricks' voxels summing to the metadata's). A
// 1.0 or 1.1 store has no page CRCs: its table is read whole once at open,
// in pages, checked as above, and its summary computed, so that it pages
// alike afterwards. What a paged open leaves to `vox-info --verify`
// (ReadAll) is the voxel sum and the block's own CRC.
//
// Thread safety: Entry, Rows and ReadAll are thread-safe; SetCapacity must
// not run concurrently with them.
#ifndef VOX_STORAGE_INTERNAL_TABLE_PAGES_H_
#define VOX_STORAGE_INTERNAL_TABLE_PAGES_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "core/util/file.h"
#include "storage/internal/format.h"
#include "storage/page_cache.h"

namespace vox::storage_internal {

class TablePages {
 public:
  // What a row must agree with.
  struct Bounds {
    const StoreMeta* meta = nullptr;
    int depth = 0;                 // levels inside a brick
    uint64_t brick_file_size = 0;
    std::string index_path, brick_path;
  };
  // `index` (kept open by the caller, outliving this) holds the table block
  // `block`; `summary` as DecodeMeta read it (page_rows 0 in a 1.0/1.1
  // store). A table of at most `whole_bytes` bytes is read and checked
  // whole now.
  static StatusOr<std::unique_ptr<TablePages>> Open(const RandomAccessFile* index,
                                                    BlockHandle block, TableSummary summary,
                                                    Bounds bounds, uint64_t whole_bytes);

  uint32_t size() const { return count_; }
  bool paged() const { return whole_.empty() && count_ > 0; }
  const TableSummary& summary() const { return summary_; }

  // Row `id` (< size()).
  StatusOr<BrickEntry> Entry(uint32_t id);
  // The rows of the page holding `id` (the whole table when it was read
  // whole), valid while `hold` lives.
  struct Rows {
    std::shared_ptr<const void> hold;
    uint32_t first = 0;  // id of rows[0]
    std::span<const BrickEntry> rows;
  };
  StatusOr<Rows> RowsOf(uint32_t id);

  // Every row in id order, with the checks of a whole read (vox-info, tests).
  StatusOr<std::vector<BrickEntry>> ReadAll() const;

  // The bytes the page cache may hold (a paged table), and what a reader
  // should count as resident: the whole table, or the cache's capacity.
  void SetCapacity(uint64_t bytes);
  uint64_t resident_bytes() const;
  // The capacity a store gives the page cache: 16 MiB (about 300,000 rows),
  // or the whole table if smaller.
  uint64_t DefaultCapacity() const;
  uint64_t bytes_read() const { return bytes_read_.load(std::memory_order_relaxed); }
  uint64_t pages_read() const { return pages_read_.load(std::memory_order_relaxed); }

 private:
  struct Page {
    std::vector<BrickEntry> rows;
  };
  TablePages(const RandomAccessFile* index, BlockHandle block, TableSummary summary,
             Bounds bounds);
  // Reads page `p`'s bytes into `bytes`.
  Status ReadPage(size_t p, std::vector<uint8_t>* bytes) const;
  // Decodes and checks the rows of page `p` (`bytes`), adding their voxels
  // to `*voxels`; `check_maxima`: also against the summary's largest brick.
  Status DecodePage(size_t p, const std::vector<uint8_t>& bytes, bool check_maxima,
                    std::vector<BrickEntry>* out, uint64_t* voxels) const;
  // Reads the table whole: every page checked, the block's CRC, the voxel
  // sum; fills the summary when `compute_summary` (a store without one);
  // returns the rows when `keep`.
  StatusOr<std::vector<BrickEntry>> ReadWhole(bool compute_summary, bool keep);
  Status CheckVoxelSum(uint64_t voxels) const;

  const RandomAccessFile* index_;
  const BlockHandle block_;
  TableSummary summary_;
  const Bounds bounds_;
  const uint32_t count_;
  std::vector<BrickEntry> whole_;  // the table, when read whole
  std::unique_ptr<ShardedPageCache<Page>> cache_;
  uint64_t capacity_ = 0;
  mutable std::atomic<uint64_t> bytes_read_{0}, pages_read_{0};
};

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_TABLE_PAGES_H_

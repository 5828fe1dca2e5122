// TablePages: see table_pages.h.
#include "storage/internal/table_pages.h"

#include <algorithm>
#include <new>

#include "core/util/crc32c.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/coding.h"

namespace vox::storage_internal {
namespace {

constexpr uint64_t kDefaultPageCacheBytes = uint64_t(16) << 20;

}  // namespace

TablePages::TablePages(const RandomAccessFile* index, BlockHandle block, TableSummary summary,
                       Bounds bounds)
    : index_(index),
      block_(block),
      summary_(std::move(summary)),
      bounds_(std::move(bounds)),
      count_(uint32_t(bounds_.meta->brick_count)) {}

StatusOr<std::unique_ptr<TablePages>> TablePages::Open(const RandomAccessFile* index,
                                                       BlockHandle block, TableSummary summary,
                                                       Bounds bounds, uint64_t whole_bytes) {
  const StoreMeta& meta = *bounds.meta;
  if (block.size != meta.brick_count * kTableEntrySize)
    return CorruptionError("'" + bounds.index_path + "': brick table is " +
                           std::to_string(block.size) + " bytes for " +
                           std::to_string(meta.brick_count) + " bricks");
  std::unique_ptr<TablePages> t(
      new TablePages(index, block, std::move(summary), std::move(bounds)));
  if (block.size <= whole_bytes) {
    VOX_ASSIGN_OR_RETURN(t->whole_, t->ReadWhole(t->summary_.page_rows == 0, /*keep=*/true));
  } else if (t->summary_.page_rows == 0) {  // 1.0/1.1: checked once, whole, then paged
    VOX_RETURN_IF_ERROR(t->ReadWhole(/*compute_summary=*/true, /*keep=*/false).status());
  }
  t->SetCapacity(t->DefaultCapacity());
  return t;
}

uint64_t TablePages::DefaultCapacity() const {
  const uint64_t all = uint64_t(count_) * sizeof(BrickEntry) +
                       summary_.pages(count_) * (sizeof(Page) + 64);
  return std::min(all, kDefaultPageCacheBytes);
}

void TablePages::SetCapacity(uint64_t bytes) {
  capacity_ = whole_.empty() ? bytes : 0;
  if (!paged()) return;
  if (cache_)
    cache_->SetCapacity(bytes);
  else
    cache_ = std::make_unique<ShardedPageCache<Page>>(bytes);
}

uint64_t TablePages::resident_bytes() const {
  return whole_.empty() ? capacity_ : whole_.size() * sizeof(BrickEntry);
}

Status TablePages::ReadPage(size_t p, std::vector<uint8_t>* bytes) const {
  const uint64_t first = uint64_t(p) * summary_.page_rows;
  const uint64_t rows = std::min<uint64_t>(summary_.page_rows, count_ - first);
  bytes->resize(rows * kTableEntrySize);
  Status s = index_->Read(block_.offset + first * kTableEntrySize, bytes->size(), bytes->data());
  bytes_read_.fetch_add(bytes->size(), std::memory_order_relaxed);
  pages_read_.fetch_add(1, std::memory_order_relaxed);
  if (!s.ok())
    return s.WithContext("reading bricks " + std::to_string(first) + ".." +
                         std::to_string(first + rows - 1) + " of the brick table");
  return OkStatus();
}

Status TablePages::DecodePage(size_t p, const std::vector<uint8_t>& bytes, bool check_maxima,
                              std::vector<BrickEntry>* out, uint64_t* voxels) const {
  const StoreMeta& meta = *bounds_.meta;
  const uint64_t first = uint64_t(p) * summary_.page_rows;
  const uint64_t bsize = bounds_.brick_file_size;
  const uint64_t brick_grid = uint64_t(1) << meta.brick_level;
  const size_t attr_bytes = AttrBytesPerVoxel(AttrFlags(meta));
  for (size_t k = 0; k * kTableEntrySize < bytes.size(); ++k) {
    const BrickEntry e = DecodeBrickEntry(bytes.data() + k * kTableEntrySize);
    auto row = [&](const std::string& m) {
      return CorruptionError("'" + bounds_.index_path + "': brick " + std::to_string(first + k) +
                             " " + m);
    };
    if (e.offset < kFileHeaderSize || e.offset > bsize ||
        uint64_t(e.stored_size) + kTrailerSize > bsize - e.offset)
      return row("record [" + std::to_string(e.offset) + ", +" + std::to_string(e.stored_size) +
                 ") lies outside '" + bounds_.brick_path + "' (" + std::to_string(bsize) +
                 " bytes)");
    if (e.codec != kCodecZstd && e.codec != kCodecRaw)
      return row("has unknown codec " + std::to_string(e.codec));
    if (e.raw_size > kMaxBrickRawBytes ||
        e.raw_size != kBrickHeaderSize + uint64_t(e.num_cells) + uint64_t(e.voxel_count) * attr_bytes)
      return row("sizes are inconsistent (" + std::to_string(e.raw_size) + " bytes, " +
                 std::to_string(e.num_cells) + " cells, " + std::to_string(e.voxel_count) +
                 " voxels)");
    if (e.num_cells == 0 || e.voxel_count == 0 ||
        e.num_cells > MaxCells(bounds_.depth, e.voxel_count))
      return row("has " + std::to_string(e.num_cells) + " cells for " +
                 std::to_string(e.voxel_count) + " voxels: impossible at depth " +
                 std::to_string(bounds_.depth));
    if (e.x >= brick_grid || e.y >= brick_grid || e.z >= brick_grid)
      return row("coordinate lies outside the brick grid");
    // A 1.2 summary bounds what the budget reserves for one brick.
    if (check_maxima &&
        (e.stored_size > summary_.max_stored_size || e.num_cells > summary_.max_num_cells ||
         e.voxel_count > summary_.max_voxel_count))
      return row("is larger than the metadata's largest brick");
    *voxels += e.voxel_count;
    if (out != nullptr) out->push_back(e);
  }
  return OkStatus();
}

Status TablePages::CheckVoxelSum(uint64_t voxels) const {
  if (bounds_.depth != 0 && voxels != bounds_.meta->voxel_count)
    return CorruptionError("'" + bounds_.index_path + "': bricks hold " + std::to_string(voxels) +
                           " voxels, the metadata says " +
                           std::to_string(bounds_.meta->voxel_count));
  return OkStatus();
}

StatusOr<std::vector<BrickEntry>> TablePages::ReadWhole(bool compute_summary, bool keep) {
  const std::string& ipath = bounds_.index_path;
  if (compute_summary) {  // pages of kTablePageRows while reading
    summary_ = TableSummary{};
    summary_.page_rows = kTablePageRows;
  }
  std::vector<BrickEntry> rows;
  uint32_t block_crc = 0;
  uint64_t voxels = 0;
  std::vector<uint8_t> bytes;
  std::vector<BrickEntry> page_rows;
  const size_t pages = summary_.pages(count_);
  for (size_t p = 0; p < pages; ++p) {
    VOX_RETURN_IF_ERROR(ReadPage(p, &bytes));
    block_crc = crc32c::Extend(block_crc, bytes.data(), bytes.size());
    const uint32_t crc = TablePageCrc(bytes.data(), bytes.size());
    if (compute_summary) {
      summary_.page_crcs.push_back(crc);
    } else if (crc != summary_.page_crcs[p]) {
      return CorruptionError("'" + ipath + "': brick table page " + std::to_string(p) +
                             " checksum mismatch");
    }
    page_rows.clear();
    VOX_RETURN_IF_ERROR(DecodePage(p, bytes, !compute_summary, &page_rows, &voxels));
    for (const BrickEntry& e : page_rows) {
      if (compute_summary) {
        summary_.max_stored_size = std::max(summary_.max_stored_size, e.stored_size);
        summary_.max_num_cells = std::max(summary_.max_num_cells, e.num_cells);
        summary_.max_voxel_count = std::max(summary_.max_voxel_count, e.voxel_count);
        summary_.sum_num_cells += e.num_cells;
      }
    }
    if (keep) rows.insert(rows.end(), page_rows.begin(), page_rows.end());
  }
  // The block's trailer: codec byte and the CRC of block and codec.
  uint8_t trailer[kTrailerSize];
  VOX_RETURN_IF_ERROR(index_->Read(block_.offset + block_.size, kTrailerSize, trailer));
  block_crc = crc32c::Extend(block_crc, trailer, 1);
  if (trailer[0] != kCodecRaw || crc32c::Unmask(DecodeFixed32(trailer + 1)) != block_crc)
    return CorruptionError("'" + ipath + "': brick table checksum mismatch (block at offset " +
                           std::to_string(block_.offset) + ", " + std::to_string(block_.size) +
                           " bytes)");
  VOX_RETURN_IF_ERROR(CheckVoxelSum(voxels));
  return rows;
}

StatusOr<std::vector<BrickEntry>> TablePages::ReadAll() const {
  if (!whole_.empty() || count_ == 0) return whole_;
  // A const copy reads the pages again, checking them all.
  TablePages copy(index_, block_, summary_, bounds_);
  return copy.ReadWhole(/*compute_summary=*/false, /*keep=*/true);
}

StatusOr<TablePages::Rows> TablePages::RowsOf(uint32_t id) {
  if (id >= count_)
    return InvalidArgumentError("brick " + std::to_string(id) + " does not exist (the table of '" +
                                bounds_.index_path + "' has " + std::to_string(count_) + " rows)");
  if (!whole_.empty()) return Rows{nullptr, 0, std::span<const BrickEntry>(whole_)};
  const size_t p = id / summary_.page_rows;
  auto page = cache_->GetOrLoad(
      p, [&]() -> StatusOr<std::pair<std::shared_ptr<const Page>, size_t>> {
        try {
          std::vector<uint8_t> bytes;
          VOX_RETURN_IF_ERROR(ReadPage(p, &bytes));
          if (TablePageCrc(bytes.data(), bytes.size()) != summary_.page_crcs[p])
            return CorruptionError("'" + bounds_.index_path + "': brick table page " +
                                   std::to_string(p) + " (bricks " +
                                   std::to_string(p * summary_.page_rows) + "..) checksum mismatch");
          auto pg = std::make_shared<Page>();
          pg->rows.reserve(bytes.size() / kTableEntrySize);
          uint64_t voxels = 0;
          VOX_RETURN_IF_ERROR(DecodePage(p, bytes, true, &pg->rows, &voxels));
          const size_t charge = pg->rows.capacity() * sizeof(BrickEntry) + sizeof(Page) + 64;
          return std::make_pair(std::shared_ptr<const Page>(std::move(pg)), charge);
        } catch (const std::bad_alloc&) {
          return ResourceExhaustedError("out of memory reading the brick table of '" +
                                        bounds_.index_path + "'");
        }
      });
  if (!page.ok()) return page.status();
  const Page& pg = **page;
  return Rows{std::move(*page), uint32_t(p * summary_.page_rows),
              std::span<const BrickEntry>(pg.rows)};
}

StatusOr<BrickEntry> TablePages::Entry(uint32_t id) {
  if (!whole_.empty() && id < whole_.size()) return whole_[id];
  VOX_ASSIGN_OR_RETURN(Rows r, RowsOf(id));
  return r.rows[id - r.first];
}

}  // namespace vox::storage_internal

// Store::Open and the store reader (storage/internal/store_reader.h): checks
// every block of the index at open, then serves bricks from the brick file
// through the page cache, reading records a window of file neighbours at a
// time (RecordWindows). Reading ahead (Prefetch) is in store_prefetch.cpp.
#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cstring>

#include <zstd.h>

#include "storage/internal/coding.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/brick_uniform.h"
#include "storage/internal/format.h"
#include "storage/internal/record_windows.h"
#include "storage/internal/store_impl.h"
#include "storage/internal/store_reader.h"
#include "core/util/memory_budget.h"
#include "storage/meta_check.h"
#include "storage/page_cache.h"
#include "storage/store.h"

namespace vox {
namespace storage_internal {
namespace {

// One decompression context per thread.
struct DCtxDeleter {
  void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
};
ZSTD_DCtx* ThreadDCtx() {
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxDeleter> dctx(ZSTD_createDCtx());
  return dctx.get();
}

// The small records a thread decoded to bricks full of one value, and that
// value: the inside of a fog is hundreds of bricks of one record, which
// then decode without decompressing (a record's bytes and its table row
// decide its brick).
class RepeatedRecords {
 public:
  static constexpr uint32_t kMaxBytes = 128;
  // The brick of a record seen before, or null.
  std::shared_ptr<DecodedBrick> Find(const uint8_t* record, const BrickEntry& e, int depth,
                                     uint8_t flags) const {
    if (e.stored_size > kMaxBytes) return nullptr;
    for (const Entry& k : entries_)
      if (k.stored_size == e.stored_size && k.raw_size == e.raw_size && k.num_cells == e.num_cells &&
          k.voxel_count == e.voxel_count && k.codec == e.codec && k.depth == depth && k.flags == flags &&
          std::memcmp(k.record, record, e.stored_size) == 0)
        return FullOfOneBrick(k.voxel, e.voxel_count, depth, flags);
    return nullptr;
  }
  void Remember(const uint8_t* record, const BrickEntry& e, int depth, uint8_t flags, const DecodedBrick& b) {
    if (e.stored_size > kMaxBytes || !b.full_of_one || b.attr_values.size() > kMaxAttrBytesPerVoxel) return;
    Entry& k = entries_[next_++ % entries_.size()];
    k.stored_size = e.stored_size;
    k.raw_size = e.raw_size;
    k.num_cells = e.num_cells;
    k.voxel_count = e.voxel_count;
    k.codec = e.codec;
    k.depth = depth;
    k.flags = flags;
    std::memcpy(k.record, record, e.stored_size);
    std::memcpy(k.voxel, b.attr_values.data(), b.attr_values.size());
  }

 private:
  struct Entry {
    uint64_t stored_size = ~uint64_t(0), raw_size = 0;
    uint32_t num_cells = 0, voxel_count = 0;
    uint8_t codec = 0, flags = 0;
    int depth = 0;
    uint8_t record[kMaxBytes];
    uint8_t voxel[kMaxAttrBytesPerVoxel];
  };
  std::array<Entry, 8> entries_{};
  size_t next_ = 0;
};

}  // namespace

Status StoreImpl::CheckBrickFits(uint32_t id, const BrickEntry& e) const {
  // Decoding holds the decompressed bytes and the decoded brick at once.
  const uint64_t need = DecodedCharge(e) + e.raw_size;
  const uint64_t allowed = std::max<uint64_t>(cache_.capacity(), kMinBrickAllowance);
  if (need <= allowed) return OkStatus();
  return ResourceExhaustedError(
      "brick " + std::to_string(id) + " of store '" + dir_ + "' would take " +
      std::to_string(need) + " bytes to decode (" + std::to_string(e.num_cells) + " cells, " +
      std::to_string(e.voxel_count) + " voxels, " + std::to_string(e.raw_size) +
      " bytes decompressed), more than the " + std::to_string(allowed) +
      " bytes the memory budget allows one brick (the brick cache): the store is corrupt, or "
      "it needs a larger brick cache");
}

StatusOr<std::shared_ptr<DecodedBrick>> StoreImpl::LoadBrick(uint32_t id) {
  VOX_ASSIGN_OR_RETURN(const BrickEntry e, table_->Entry(id));
  VOX_RETURN_IF_ERROR(CheckBrickFits(id, e));
  // Read the record (with its window's neighbours, or alone), then check
  // and decode it.
  thread_local std::vector<uint8_t> record;
  struct Trim {  // scratch grows to the largest brick seen; an outsized one is not kept
    ~Trim() {
      if (record.capacity() > (size_t(64) << 20)) std::vector<uint8_t>().swap(record);
    }
  } trim;
  VOX_ASSIGN_OR_RETURN(RecordWindows::Record r, windows_->Read(id, e, &record));
  auto b = DecodeRecord(id, e, r.data);
  if (!b.ok() && r.hold) windows_->Forget(e);  // bad bytes are not cached, as read errors are not
  return b;
}

StatusOr<std::shared_ptr<DecodedBrick>> StoreImpl::DecodeRecord(uint32_t id, const BrickEntry& e,
                                                                const uint8_t* record) {
  VOX_RETURN_IF_ERROR(CheckBrickFits(id, e));
  const std::string& path = bricks_->path();
  auto where = [&] {
    return "brick " + std::to_string(id) + " (offset " + std::to_string(e.offset) + ") in '" +
           path + "'";
  };
  thread_local std::vector<uint8_t> raw;
  struct Trim {
    ~Trim() {
      if (raw.capacity() > (size_t(64) << 20)) std::vector<uint8_t>().swap(raw);
    }
  } trim;
  if (options_.verify_checksums) {
    auto codec = CheckTrailer(record, e.stored_size, "brick " + std::to_string(id), path,
                              e.offset);
    if (!codec.ok()) return codec.status();
    if (DecodeFixed32(record + e.stored_size + 1) != e.crc)
      return CorruptionError(where() + ": record checksum differs from the brick table's");
  }
  uint8_t codec = record[e.stored_size];
  if (codec != e.codec)
    return CorruptionError(where() + ": codec " + std::to_string(codec) +
                           " differs from the brick table's " + std::to_string(e.codec));
  thread_local RepeatedRecords repeated;
  if (auto b = repeated.Find(record, e, depth_, flags_)) return b;
  const uint8_t* bytes = record;
  if (codec == kCodecZstd) {
    unsigned long long content = ZSTD_getFrameContentSize(record, e.stored_size);
    if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN ||
        content != e.raw_size)
      return CorruptionError(where() + ": zstd frame content size " +
                             (content == ZSTD_CONTENTSIZE_ERROR     ? std::string("unreadable")
                              : content == ZSTD_CONTENTSIZE_UNKNOWN ? std::string("missing")
                                                                    : std::to_string(content)) +
                             ", the brick table says " + std::to_string(e.raw_size));
    ZSTD_DCtx* dctx = ThreadDCtx();
    if (dctx == nullptr) return ResourceExhaustedError("cannot allocate a zstd context");
    // (grown, never shrunk: a resize back up would zero the bytes zstd writes)
    if (raw.size() < e.raw_size) raw.resize(e.raw_size);
    size_t n = ZSTD_decompressDCtx(dctx, raw.data(), e.raw_size, record, e.stored_size);
    if (ZSTD_isError(n))
      return CorruptionError(where() + ": zstd: " + ZSTD_getErrorName(n));
    if (n != e.raw_size)
      return CorruptionError(where() + ": decompressed to " + std::to_string(n) +
                             " bytes, the brick table says " + std::to_string(e.raw_size));
    bytes = raw.data();
  } else if (codec == kCodecRaw) {
    if (e.stored_size != e.raw_size)
      return CorruptionError(where() + ": raw brick of " + std::to_string(e.stored_size) +
                             " bytes, the brick table says " + std::to_string(e.raw_size));
  } else {
    return CorruptionError(where() + ": unknown codec " + std::to_string(codec));
  }
  auto b = DecodeBrickRaw(bytes, e.raw_size, e, depth_, flags_);
  if (!b.ok()) return b.status().WithContext(where());
  bytes_decompressed_.fetch_add(e.raw_size, std::memory_order_relaxed);
  repeated.Remember(record, e, depth_, flags_, **b);
  return b;
}

namespace {

// The index file's header and footer, checked to belong to one store.
struct IndexEnds {
  FileHeader header;
  Footer footer;
};

StatusOr<IndexEnds> ReadIndexEnds(RandomAccessFile& index) {
  const std::string& ipath = index.path();
  const uint64_t isize = index.size();
  if (isize < kFileHeaderSize + kFooterSize)
    return CorruptionError("'" + ipath + "' is " + std::to_string(isize) +
                           " bytes: truncated (a store index has at least " +
                           std::to_string(kFileHeaderSize + kFooterSize) + ")");
  uint8_t head[kFileHeaderSize], foot[kFooterSize];
  VOX_RETURN_IF_ERROR(index.Read(0, kFileHeaderSize, head));
  IndexEnds e;
  VOX_ASSIGN_OR_RETURN(e.header, DecodeFileHeader(head, kIndexMagic, ipath));
  VOX_RETURN_IF_ERROR(index.Read(isize - kFooterSize, kFooterSize, foot));
  VOX_ASSIGN_OR_RETURN(e.footer, DecodeFooter(foot, ipath));
  if (e.footer.store_id != e.header.store_id)
    return CorruptionError("'" + ipath + "': header and footer belong to different stores");
  return e;
}

// Whether block `h` (with its trailer) lies between the index's header and footer.
bool BlockInFile(const BlockHandle& h, uint64_t isize) {
  const uint64_t blocks_end = isize - kFooterSize;
  return h.offset >= kFileHeaderSize && h.offset <= blocks_end && h.size <= blocks_end - h.offset &&
         kTrailerSize <= blocks_end - h.offset - h.size;
}

Status BlockOutsideFile(const RandomAccessFile& index, const BlockHandle& h, const char* what) {
  return CorruptionError("'" + index.path() + "': " + what + " block [" +
                         std::to_string(h.offset) + ", +" + std::to_string(h.size) +
                         ") lies outside the file (" + std::to_string(index.size()) + " bytes)");
}

// An index block into *out: in bounds, checksum, raw codec (the index is
// small: always verified).
Status ReadIndexBlock(RandomAccessFile& index, const BlockHandle& h, const char* what,
                      std::vector<uint8_t>* out) {
  const std::string& ipath = index.path();
  if (!BlockInFile(h, index.size())) return BlockOutsideFile(index, h, what);
  out->resize(h.size + kTrailerSize);
  VOX_RETURN_IF_ERROR(index.Read(h.offset, out->size(), out->data()));
  VOX_ASSIGN_OR_RETURN(uint8_t codec, CheckTrailer(out->data(), h.size, what, ipath, h.offset));
  if (codec != kCodecRaw)
    return CorruptionError("'" + ipath + "': " + what + " block has unknown codec " +
                           std::to_string(codec));
  out->resize(h.size);
  return OkStatus();
}

// What reading the index takes at its peak: the top's block and its copy
// as cells, its traversal form, the top attributes, and a table read whole
// (its bytes and rows); refused beyond the budget.
Status CheckOpenBudget(const Footer& f, const OpenOptions& options, const std::string& dir) {
  if (options.budget_bytes == 0) return OkStatus();
  const uint64_t cells = f.top.size / sizeof(Cell);
  const uint64_t need = f.meta.size + 2 * f.top.size + cells * sizeof(CompactCell) +
                        2 * f.top_attr.size +
                        (f.table.size <= options.whole_table_bytes
                             ? f.table.size + f.table.size / kTableEntrySize * sizeof(BrickEntry)
                             : 0);
  if (need <= options.budget_bytes) return OkStatus();
  return ResourceExhaustedError(
      "store '" + dir + "' needs about " + std::to_string((need >> 20) + 1) +
      " MiB to open (its resident top of " + std::to_string(cells) +
      " cells), more than the memory budget of " + std::to_string(options.budget_bytes >> 20) +
      " MiB: give the job more memory (--memory-mb, or the job's limit)");
}

// The bricks file: header, size, same store as the index.
Status CheckBrickFile(RandomAccessFile& bricks, const IndexEnds& ends, const std::string& ipath) {
  const std::string& bpath = bricks.path();
  const Footer& f = ends.footer;
  if (bricks.size() < kFileHeaderSize)
    return CorruptionError("'" + bpath + "' is " + std::to_string(bricks.size()) +
                           " bytes: truncated (the index expects " +
                           std::to_string(f.brick_file_size) + ")");
  uint8_t head[kFileHeaderSize];
  VOX_RETURN_IF_ERROR(bricks.Read(0, kFileHeaderSize, head));
  VOX_ASSIGN_OR_RETURN(FileHeader bh, DecodeFileHeader(head, kBrickMagic, bpath));
  if (bh.store_id != ends.header.store_id)
    return CorruptionError("'" + bpath + "' belongs to a different store than '" + ipath + "'");
  if (bricks.size() != f.brick_file_size)
    return CorruptionError("'" + bpath + "' is " + std::to_string(bricks.size()) +
                           " bytes; the index expects " + std::to_string(f.brick_file_size) +
                           (bricks.size() < f.brick_file_size ? " (truncated)" : ""));
  return OkStatus();
}

}  // namespace

// The top: size, then structure (every ref in range, bricks only at the
// brick level); a top-only store's attributes.
Status StoreImpl::LoadTop(const std::vector<uint8_t>& top_b, std::vector<uint8_t> attr_b,
                          uint64_t table_size, const std::string& ipath) {
  auto bad = [&](const std::string& m) { return CorruptionError("'" + ipath + "': " + m); };
  if (top_b.size() != meta_.top_cells * sizeof(Cell))
    return bad("top octree block is " + std::to_string(top_b.size()) + " bytes for " +
               std::to_string(meta_.top_cells) + " cells");
  std::vector<Cell> top_cells(meta_.top_cells);
  std::memcpy(top_cells.data(), top_b.data(), top_b.size());
  const bool top_only = depth_ == 0;
  if (top_only) {
    if (meta_.brick_count != 0 || table_size != 0) return bad("a top-only store has bricks");
    if (meta_.voxel_count >= kBrickBit) return bad("too many voxels for a top-only store");
    if (attr_b.size() != meta_.voxel_count * AttrBytesPerVoxel(flags_))
      return bad("top attribute block is " + std::to_string(attr_b.size()) + " bytes for " +
                 std::to_string(meta_.voxel_count) + " voxels");
    top_attr_ = PlanesToValues(attr_b, uint32_t(meta_.voxel_count), flags_);
  } else if (!attr_b.empty()) {
    return bad("a store with bricks has top attributes");
  }
  Status vs = ValidatePool(top_cells.data(), top_cells.size(), meta_.brick_level, !top_only,
                           top_only ? meta_.voxel_count : meta_.brick_count);
  if (!vs.ok()) return vs.WithContext("'" + ipath + "': top");
  // In memory the top is level order; brick ids (payloads when top-only) must
  // be consecutive in it, i.e. assigned in Morton order as FORMAT.md says.
  auto compact = LevelOrderPool(top_cells, meta_.brick_level, !top_only);
  if (!compact.ok()) return compact.status().WithContext("'" + ipath + "': top");
  top_ = std::move(*compact);
  return CheckMetaAgainstTop(meta_, top_, ipath);  // bbox vs occupied bricks
}

Status StoreImpl::Load(std::unique_ptr<RandomAccessFile> index,
                       std::unique_ptr<RandomAccessFile> bricks) {
  const std::string& ipath = index->path();
  VOX_ASSIGN_OR_RETURN(IndexEnds ends, ReadIndexEnds(*index));
  const Footer& f = ends.footer;
  store_id_ = ends.header.store_id;
  VOX_RETURN_IF_ERROR(CheckOpenBudget(f, options_, dir_));
  std::vector<uint8_t> meta_b, top_b, attr_b;
  VOX_RETURN_IF_ERROR(ReadIndexBlock(*index, f.meta, "metadata", &meta_b));
  VOX_RETURN_IF_ERROR(ReadIndexBlock(*index, f.top, "top octree", &top_b));
  VOX_RETURN_IF_ERROR(ReadIndexBlock(*index, f.top_attr, "top attributes", &attr_b));
  if (!BlockInFile(f.table, index->size()))  // read by TablePages, whole or a page at a time
    return BlockOutsideFile(*index, f.table, "brick table");
  TableSummary summary;
  VOX_ASSIGN_OR_RETURN(meta_, DecodeMeta(meta_b.data(), meta_b.size(), ipath, &summary));
  depth_ = meta_.levels - meta_.brick_level;
  flags_ = AttrFlags(meta_);
  VOX_RETURN_IF_ERROR(LoadTop(top_b, std::move(attr_b), f.table.size, ipath));
  VOX_RETURN_IF_ERROR(CheckBrickFile(*bricks, ends, ipath));

  // The brick table: read whole now if small, else a page at a time when used.
  TablePages::Bounds bounds{&meta_, depth_, f.brick_file_size, ipath, bricks->path()};
  VOX_ASSIGN_OR_RETURN(table_, TablePages::Open(index.get(), f.table, std::move(summary),
                                                std::move(bounds), options_.whole_table_bytes));
  index_ = std::move(index);
  bricks_ = std::move(bricks);
  windows_ = std::make_unique<RecordWindows>(bricks_.get(), table_.get());
  SetCacheCapacity(options_.cache_bytes);
  return OkStatus();
}

StatusOr<std::unique_ptr<Store>> OpenStoreFromFiles(const std::string& dir,
                                                    std::unique_ptr<RandomAccessFile> index,
                                                    std::unique_ptr<RandomAccessFile> bricks,
                                                    const OpenOptions& options) {
  auto store = std::make_unique<StoreImpl>(dir, options);
  VOX_RETURN_IF_ERROR(store->Load(std::move(index), std::move(bricks)));
  return std::unique_ptr<Store>(std::move(store));
}

StatusOr<std::vector<BrickEntry>> BrickTable(const Store& store) {
  return static_cast<const StoreImpl&>(store).table().ReadAll();
}

}  // namespace storage_internal

StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& dir, const OpenOptions& options) {
  struct stat st;
  if (stat(dir.c_str(), &st) != 0)
    return NotFoundError("store '" + dir + "' does not exist");
  if (!S_ISDIR(st.st_mode))
    return InvalidArgumentError("'" + dir + "' is not a store directory");
  std::string base = dir;
  while (base.size() > 1 && base.back() == '/') base.pop_back();
  if (!options.unfinished_ingest &&
      stat((base + "/" + storage_internal::kJournalFileName).c_str(), &st) == 0)
    return InvalidArgumentError("'" + base + "' is an unfinished resumable ingest (it holds " +
                                "its journal), not a store: vox-ingest --resume finishes it");
  // Both files are read with pread: the index once, sequentially, at open;
  // bricks as random reads without the kernel's read-ahead (a fault's
  // read-around on a mapping, or the kernel's read-ahead, would read
  // megabytes per brick on disks with a large read_ahead_kb, outside any
  // budget, thrashing under a memory limit). Instead a miss reads its
  // record's window, sized and cached within the budget (RecordWindows).
  auto open = [&](const char* name, bool random_access) {
    auto f = OpenPreadFile(base + "/" + name, random_access);
    if (!f.ok() && f.status().code() == StatusCode::kNotFound)
      return StatusOr<std::unique_ptr<RandomAccessFile>>(
          f.status().WithContext("'" + base + "' is not a complete vox store"));
    return f;
  };
  VOX_ASSIGN_OR_RETURN(auto index, open(storage_internal::kIndexFileName, false));
  VOX_ASSIGN_OR_RETURN(auto bricks, open(storage_internal::kBrickFileName, true));
  return storage_internal::OpenStoreFromFiles(base, std::move(index), std::move(bricks), options);
}

}  // namespace vox

// Store::Open and the store reader: checks every block of the index at open,
// then serves bricks from the brick file through the page cache, reading
// records a window of file neighbours at a time (RecordWindows), and reads
// requested bricks ahead on I/O threads (Prefetch).
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <mutex>
#include <new>
#include <thread>

#include <zstd.h>

#include "storage/internal/coding.h"
#include "storage/internal/format.h"
#include "storage/internal/record_windows.h"
#include "storage/internal/store_impl.h"
#include "storage/memory_budget.h"
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

class StoreImpl : public Store {
 public:
  StoreImpl(std::string dir, const OpenOptions& options)
      : dir_(std::move(dir)), options_(options), cache_(options.cache_bytes) {}
  ~StoreImpl() override {
    {
      std::lock_guard<std::mutex> lock(pf_mu_);
      pf_stop_ = true;
    }
    pf_generation_.fetch_add(1);
    pf_cv_.notify_all();
    for (std::thread& t : pf_threads_) t.join();
  }

  Status Load(std::unique_ptr<RandomAccessFile> index, std::unique_ptr<RandomAccessFile> bricks);

  const StoreMeta& meta() const override { return meta_; }
  OctreeView view() override {
    return {meta_.levels, meta_.brick_level, top_.data(), uint32_t(top_.size()), this};
  }

  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    VOX_ASSIGN_OR_RETURN(auto b, Get(id));
    const DecodedBrick* data = b.get();
    return BrickView{b->cells.data(), uint32_t(b->cells.size()), std::move(b), data};
  }

  StatusOr<BrickView> FetchBrickIfReady(uint32_t id) override {
    std::shared_ptr<const DecodedBrick> b = id < table_.size() ? cache_.Peek(id) : nullptr;
    if (!b) {
      if (id >= table_.size()) return Get(id).status();  // the error naming the bad id
      return UnavailableError("brick " + std::to_string(id) + " of store '" + dir_ +
                              "' is not in memory");
    }
    const DecodedBrick* data = b.get();
    return BrickView{b->cells.data(), uint32_t(b->cells.size()), std::move(b), data};
  }

  StatusOr<VoxelAttributes> Attributes(uint32_t brick, uint32_t payload) override {
    if (brick == kNoBrick) {
      if (meta_.brick_level != meta_.levels || payload >= meta_.voxel_count)
        return InvalidArgumentError("payload " + std::to_string(payload) +
                                    " is not a voxel of the top of store '" + dir_ + "'");
      return ReadAttributes(top_attr_.data(), uint32_t(meta_.voxel_count), flags_, payload);
    }
    VOX_ASSIGN_OR_RETURN(auto b, Get(brick));
    return BrickAttributes(*b, brick, payload);
  }

  StatusOr<VoxelAttributes> HitAttributes(const Hit& hit) override {
    if (hit.brick_data == nullptr || hit.brick == kNoBrick) return Attributes(hit.brick, hit.payload);
    return BrickAttributes(*static_cast<const DecodedBrick*>(hit.brick_data), hit.brick,
                           hit.payload);
  }

  CacheStats cache_stats() const override {
    PageCacheCounters c = cache_.counters();
    CacheStats s;
    s.hits = c.hits;
    s.misses = c.misses;
    s.evictions = c.evictions;
    s.bytes_mapped = bricks_ ? bricks_->size() : 0;
    s.bytes_decompressed = bytes_decompressed_.load(std::memory_order_relaxed);
    s.bytes_resident = c.charge + (windows_ ? windows_->charge() : 0);
    s.capacity = c.capacity + (windows_ ? windows_->capacity() : 0);
    s.prefetched = c.prefetched;
    s.prefetch_hits = c.prefetch_hits;
    s.prefetch_dropped = pf_dropped_.load(std::memory_order_relaxed);
    s.prefetch_failed = pf_failed_.load(std::memory_order_relaxed);
    s.bytes_read = bytes_read_.load(std::memory_order_relaxed) +
                   (windows_ ? windows_->bytes_read() : 0);
    s.windows_read = windows_ ? windows_->windows_read() : 0;
    s.window_bytes = windows_ ? windows_->window_bytes() : 0;
    auto io = ProcessIoBytes();
    s.process_read_bytes = io.ok() ? *io : 0;
    return s;
  }

  std::string description() const override { return dir_; }
  void Prefetch(std::span<const uint32_t> brick_ids) override;
  uint64_t PrefetchBacklog() const override {
    return pf_queued_raw_.load(std::memory_order_relaxed) + cache_.PrefetchUnused();
  }
  void CancelPrefetch() override {
    std::lock_guard<std::mutex> lock(pf_mu_);
    for (const Run& r : pf_queue_) pf_dropped_.fetch_add(r.ids.size(), std::memory_order_relaxed);
    pf_queue_.clear();
    pf_queued_bricks_ = 0;
    pf_queued_raw_.store(0, std::memory_order_relaxed);
    pf_generation_.fetch_add(1);  // runs being read finish; none starts under the old generation
  }
  uint64_t store_id() const override { return store_id_; }

  uint64_t resident_bytes() const override {
    return top_.size() * sizeof(CompactCell) + top_attr_.size() +
           table_.size() * (sizeof(BrickEntry) + sizeof(uint32_t));  // + RecordWindows' order
  }

  BrickSizes brick_sizes() const override {
    BrickSizes z;
    uint64_t sum = 0;
    for (const BrickEntry& e : table_) {
      const uint64_t decoded = DecodedCharge(e);
      z.max_decoded = std::max(z.max_decoded, decoded);
      z.max_stored = std::max<uint64_t>(z.max_stored, uint64_t(e.stored_size) + kTrailerSize);
      sum += decoded;
    }
    if (!table_.empty()) z.mean_decoded = sum / table_.size();
    return z;
  }

  // The brick cache's bytes: decoded bricks, and a share for record windows
  // (RecordWindows::ShareOf) unless OpenOptions::read_windows is off.
  void SetCacheCapacity(uint64_t bytes) override {
    uint64_t windows = 0;
    if (windows_ && options_.read_windows) {
      windows_->SetCapacity(RecordWindows::ShareOf(bytes));
      windows = windows_->capacity();
    }
    cache_.SetCapacity(size_t(bytes - windows));
  }

  const std::vector<BrickEntry>& table() const { return table_; }

 private:
  StatusOr<std::shared_ptr<const DecodedBrick>> Get(uint32_t id) {
    if (id >= table_.size())
      return InvalidArgumentError("brick " + std::to_string(id) + " does not exist (store '" +
                                  dir_ + "' has " + std::to_string(table_.size()) + " bricks)");
    return cache_.GetOrLoad(id, [&]() -> StatusOr<std::pair<std::shared_ptr<const DecodedBrick>,
                                                            size_t>> {
      StatusOr<std::shared_ptr<DecodedBrick>> b = InternalError("unreached");
      try {
        b = LoadBrick(id);
      } catch (const std::bad_alloc&) {
        b = ResourceExhaustedError("out of memory decoding brick " + std::to_string(id) +
                                   " of store '" + dir_ + "'");
      } catch (const std::exception& e) {  // never leave single-flight waiters hanging
        b = InternalError("decoding brick " + std::to_string(id) + " of store '" + dir_ +
                          "': " + e.what());
      }
      if (!b.ok()) return b.status();
      size_t charge = (*b)->charge();
      return std::make_pair(std::shared_ptr<const DecodedBrick>(std::move(*b)), charge);
    });
  }

  // What the cache charges for the brick of entry `e` once decoded
  // (DecodedBrick::charge() of its cells and attribute planes).
  uint64_t DecodedCharge(const BrickEntry& e) const {
    // As DecodedBrick::charge() counts a decoded brick (its capacities are its sizes).
    return sizeof(DecodedBrick) + uint64_t(e.num_cells) * sizeof(CompactCell) +
           uint64_t(e.voxel_count) * AttrBytesPerVoxel(flags_) + DecodedBrick::kOverheadBytes;
  }
  // A brick is decoded only if it fits what the budget gives one brick: the
  // brick cache's capacity, or kMinBrickAllowance if that is smaller (a tiny
  // cache still decodes ordinary bricks and evicts them at once). Checked
  // from the table row, before anything is allocated or read.
  static constexpr uint64_t kMinBrickAllowance = uint64_t(4) << 20;
  Status CheckBrickFits(uint32_t id) const;
  StatusOr<std::shared_ptr<DecodedBrick>> LoadBrick(uint32_t id);
  // Checks and decodes brick `id` from its record (stored_size + trailer bytes).
  StatusOr<std::shared_ptr<DecodedBrick>> DecodeRecord(uint32_t id, const uint8_t* record);
  // A run of bricks neighbouring in the brick file, in file order, read with
  // one pread.
  struct Run {
    std::vector<uint32_t> ids;
    uint64_t raw = 0;  // their decoded charge
  };
  void PrefetchLoop();
  void ReadRun(const Run& run, uint64_t generation, std::vector<uint8_t>* buf);

  StatusOr<VoxelAttributes> BrickAttributes(const DecodedBrick& b, uint32_t brick,
                                            uint32_t payload) const {
    if (payload >= b.voxel_count)
      return InvalidArgumentError("payload " + std::to_string(payload) + " outside brick " +
                                  std::to_string(brick) + " (" + std::to_string(b.voxel_count) +
                                  " voxels) of store '" + dir_ + "'");
    return ReadAttributes(b.attr_planes.data(), b.voxel_count, b.flags, payload);
  }

  const std::string dir_;
  const OpenOptions options_;
  StoreMeta meta_;
  int depth_ = 0;
  uint64_t store_id_ = 0;
  uint8_t flags_ = 0;
  std::vector<CompactCell> top_;  // traversal form (the file holds the build form)
  std::vector<uint8_t> top_attr_;
  std::vector<BrickEntry> table_;
  std::unique_ptr<RandomAccessFile> bricks_;
  std::unique_ptr<RecordWindows> windows_;  // reads records; set by Load
  ShardedPageCache<DecodedBrick> cache_;
  std::atomic<uint64_t> bytes_decompressed_{0};
  std::atomic<uint64_t> bytes_read_{0};

  // Prefetch: runs queue under pf_mu_; io_threads threads, started by the
  // first Prefetch, serve them until the store closes.
  mutable std::mutex pf_mu_;
  std::condition_variable pf_cv_;
  std::deque<Run> pf_queue_;
  size_t pf_queued_bricks_ = 0;
  std::atomic<uint64_t> pf_queued_raw_{0};
  bool pf_stop_ = false;
  std::vector<std::thread> pf_threads_;
  std::atomic<uint64_t> pf_generation_{0};  // bumped by CancelPrefetch and close
  std::atomic<uint64_t> pf_dropped_{0}, pf_failed_{0};
};

// Queue bound, and how reads of neighbouring bricks merge: a gap up to
// kMaxGap joins the run while the run's gap bytes stay under half its brick
// bytes (plus a page), so a run never reads more than 1.5x what it needs.
// kMaxRun bounds each I/O thread's buffer (the memory budget counts it).
constexpr size_t kMaxPrefetchQueue = size_t(1) << 16;  // bricks
constexpr uint64_t kMaxGap = 4 << 10;  // a page: measured 7% fewer bytes than 32 KiB, same time
constexpr uint64_t kMaxRun = kPrefetchRunBytes;

void StoreImpl::Prefetch(std::span<const uint32_t> brick_ids) {
  if (brick_ids.empty() || table_.empty()) return;
  std::vector<uint32_t> ids;
  ids.reserve(brick_ids.size());
  for (uint32_t id : brick_ids)
    if (id < table_.size() && !cache_.Contains(id)) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  // File order (records lie in the order the ingest wrote them: spatial
  // neighbours close together), so neighbours merge into runs.
  std::sort(ids.begin(), ids.end(),
            [&](uint32_t a, uint32_t b) { return table_[a].offset < table_[b].offset; });
  std::vector<Run> runs;
  for (size_t i = 0; i < ids.size();) {
    const uint64_t begin = table_[ids[i]].offset;
    uint64_t end = begin + table_[ids[i]].stored_size + kTrailerSize;
    uint64_t useful = end - begin, gaps = 0;
    Run run;
    run.ids.push_back(ids[i]);
    run.raw = DecodedCharge(table_[ids[i]]);
    size_t j = i + 1;
    for (; j < ids.size(); ++j) {
      const BrickEntry& e = table_[ids[j]];
      const uint64_t size = e.stored_size + kTrailerSize;
      const uint64_t gap = e.offset >= end ? e.offset - end : 0;
      if (e.offset < end || gap > kMaxGap || 2 * (gaps + gap) > useful + size + 8192 ||
          e.offset + size - begin > kMaxRun)
        break;
      gaps += gap;
      useful += size;
      end = e.offset + size;
      run.ids.push_back(ids[j]);
      run.raw += DecodedCharge(e);
    }
    runs.push_back(std::move(run));
    i = j;
  }
  if (runs.empty()) return;
  {
    std::lock_guard<std::mutex> lock(pf_mu_);
    if (pf_stop_) return;
    const int n = std::max(1, options_.io_threads);
    while (int(pf_threads_.size()) < n) pf_threads_.emplace_back([this] { PrefetchLoop(); });
    for (Run& r : runs) {
      pf_queued_bricks_ += r.ids.size();
      pf_queued_raw_.fetch_add(r.raw, std::memory_order_relaxed);
      pf_queue_.push_back(std::move(r));
    }
    while (pf_queued_bricks_ > kMaxPrefetchQueue && !pf_queue_.empty()) {  // oldest first
      const Run& r = pf_queue_.front();
      pf_queued_bricks_ -= r.ids.size();
      pf_queued_raw_.fetch_sub(r.raw, std::memory_order_relaxed);
      pf_dropped_.fetch_add(r.ids.size(), std::memory_order_relaxed);
      pf_queue_.pop_front();
    }
  }
  pf_cv_.notify_all();
}

void StoreImpl::PrefetchLoop() {
  std::vector<uint8_t> buf;
  for (;;) {
    Run run;
    uint64_t generation;
    {
      std::unique_lock<std::mutex> lock(pf_mu_);
      pf_cv_.wait(lock, [&] { return pf_stop_ || !pf_queue_.empty(); });
      if (pf_stop_) return;
      run = std::move(pf_queue_.front());
      pf_queue_.pop_front();
      pf_queued_bricks_ -= run.ids.size();
      pf_queued_raw_.fetch_sub(run.raw, std::memory_order_relaxed);
      generation = pf_generation_.load();
    }
    ReadRun(run, generation, &buf);
    if (buf.capacity() > 2 * kMaxRun) std::vector<uint8_t>().swap(buf);
  }
}

void StoreImpl::ReadRun(const Run& run, uint64_t generation, std::vector<uint8_t>* buf) {
  // Tight: what this run would add evicts what was read ahead before use.
  if (cache_.PrefetchUnused() + run.raw > cache_.capacity() / 2) {
    pf_dropped_.fetch_add(run.ids.size(), std::memory_order_relaxed);
    return;
  }
  // Claim the bricks nobody has cached or started meanwhile: from here their
  // fetches wait for this read instead of making their own.
  std::vector<uint32_t> claimed;
  claimed.reserve(run.ids.size());
  for (uint32_t id : run.ids)
    if (cache_.Claim(id)) claimed.push_back(id);
  if (claimed.empty()) return;
  size_t next = 0;  // claimed[next..] still to finish
  auto release_rest = [&] {
    for (; next < claimed.size(); ++next) cache_.FinishClaim(claimed[next], nullptr, 0);
  };
  if (pf_generation_.load() != generation) {  // cancelled or closing
    pf_dropped_.fetch_add(claimed.size(), std::memory_order_relaxed);
    release_rest();
    return;
  }
  const uint64_t begin = table_[claimed.front()].offset;
  const uint64_t end = table_[claimed.back()].offset + table_[claimed.back()].stored_size + kTrailerSize;
  try {
    buf->resize(end - begin);
    Status rs = bricks_->Read(begin, buf->size(), buf->data());
    bytes_read_.fetch_add(buf->size(), std::memory_order_relaxed);
    if (!rs.ok()) {  // each brick's own fetch reads it again and reports
      pf_failed_.fetch_add(claimed.size(), std::memory_order_relaxed);
      release_rest();
      return;
    }
    for (; next < claimed.size(); ++next) {
      const uint32_t id = claimed[next];
      auto b = DecodeRecord(id, buf->data() + (table_[id].offset - begin));
      if (!b.ok()) {
        pf_failed_.fetch_add(1, std::memory_order_relaxed);
        cache_.FinishClaim(id, nullptr, 0);
        continue;
      }
      const size_t charge = (*b)->charge();
      cache_.FinishClaim(id, std::shared_ptr<const DecodedBrick>(std::move(*b)), charge);
    }
  } catch (const std::exception&) {  // out of memory: the fetches try again
    pf_failed_.fetch_add(claimed.size() - next, std::memory_order_relaxed);
    release_rest();
  }
}

Status StoreImpl::CheckBrickFits(uint32_t id) const {
  const BrickEntry& e = table_[id];
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
  VOX_RETURN_IF_ERROR(CheckBrickFits(id));
  // Read the record (with its window's neighbours, or alone), then check
  // and decode it.
  thread_local std::vector<uint8_t> record;
  struct Trim {  // scratch grows to the largest brick seen; an outsized one is not kept
    ~Trim() {
      if (record.capacity() > (size_t(64) << 20)) std::vector<uint8_t>().swap(record);
    }
  } trim;
  VOX_ASSIGN_OR_RETURN(RecordWindows::Record r, windows_->Read(id, &record));
  auto b = DecodeRecord(id, r.data);
  if (!b.ok() && r.hold) windows_->Forget(id);  // bad bytes are not cached, as read errors are not
  return b;
}

StatusOr<std::shared_ptr<DecodedBrick>> StoreImpl::DecodeRecord(uint32_t id,
                                                                const uint8_t* record) {
  VOX_RETURN_IF_ERROR(CheckBrickFits(id));
  const BrickEntry& e = table_[id];
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
    raw.resize(e.raw_size);
    size_t n = ZSTD_decompressDCtx(dctx, raw.data(), raw.size(), record, e.stored_size);
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
  return b;
}

Status StoreImpl::Load(std::unique_ptr<RandomAccessFile> index,
                       std::unique_ptr<RandomAccessFile> bricks) {
  const std::string& ipath = index->path();
  const uint64_t isize = index->size();
  if (isize < kFileHeaderSize + kFooterSize)
    return CorruptionError("'" + ipath + "' is " + std::to_string(isize) +
                           " bytes: truncated (a store index has at least " +
                           std::to_string(kFileHeaderSize + kFooterSize) + ")");
  uint8_t head[kFileHeaderSize], foot[kFooterSize];
  VOX_RETURN_IF_ERROR(index->Read(0, kFileHeaderSize, head));
  VOX_ASSIGN_OR_RETURN(FileHeader ih, DecodeFileHeader(head, kIndexMagic, ipath));
  VOX_RETURN_IF_ERROR(index->Read(isize - kFooterSize, kFooterSize, foot));
  auto footer_or = DecodeFooter(foot, ipath);
  if (!footer_or.ok()) return footer_or.status();
  const Footer f = *footer_or;
  if (f.store_id != ih.store_id)
    return CorruptionError("'" + ipath + "': header and footer belong to different stores");
  store_id_ = ih.store_id;

  // Each block: in bounds, checksum, raw codec.
  const uint64_t blocks_end = isize - kFooterSize;
  auto read_block = [&](const BlockHandle& h, const char* what,
                        std::vector<uint8_t>* out) -> Status {
    if (h.offset < kFileHeaderSize || h.offset > blocks_end || h.size > blocks_end - h.offset ||
        kTrailerSize > blocks_end - h.offset - h.size)
      return CorruptionError("'" + ipath + "': " + what + " block [" + std::to_string(h.offset) +
                             ", +" + std::to_string(h.size) + ") lies outside the file (" +
                             std::to_string(isize) + " bytes)");
    out->resize(h.size + kTrailerSize);
    VOX_RETURN_IF_ERROR(index->Read(h.offset, out->size(), out->data()));
    {  // the index is small: always verified
      VOX_ASSIGN_OR_RETURN(uint8_t codec, CheckTrailer(out->data(), h.size, what, ipath, h.offset));
      if (codec != kCodecRaw)
        return CorruptionError("'" + ipath + "': " + what + " block has unknown codec " +
                               std::to_string(codec));
    }
    out->resize(h.size);
    return OkStatus();
  };
  std::vector<uint8_t> meta_b, top_b, attr_b, table_b;
  VOX_RETURN_IF_ERROR(read_block(f.meta, "metadata", &meta_b));
  VOX_RETURN_IF_ERROR(read_block(f.top, "top octree", &top_b));
  VOX_RETURN_IF_ERROR(read_block(f.top_attr, "top attributes", &attr_b));
  VOX_RETURN_IF_ERROR(read_block(f.table, "brick table", &table_b));
  VOX_ASSIGN_OR_RETURN(meta_, DecodeMeta(meta_b.data(), meta_b.size(), ipath));
  depth_ = meta_.levels - meta_.brick_level;
  flags_ = AttrFlags(meta_);
  auto bad = [&](const std::string& m) { return CorruptionError("'" + ipath + "': " + m); };

  // The top: size, then structure (every ref in range, bricks only at the brick level).
  if (top_b.size() != meta_.top_cells * sizeof(Cell))
    return bad("top octree block is " + std::to_string(top_b.size()) + " bytes for " +
               std::to_string(meta_.top_cells) + " cells");
  std::vector<Cell> top_cells(meta_.top_cells);
  std::memcpy(top_cells.data(), top_b.data(), top_b.size());
  const bool top_only = depth_ == 0;
  if (top_only) {
    if (meta_.brick_count != 0 || !table_b.empty()) return bad("a top-only store has bricks");
    if (meta_.voxel_count >= kBrickBit) return bad("too many voxels for a top-only store");
    if (attr_b.size() != meta_.voxel_count * AttrBytesPerVoxel(flags_))
      return bad("top attribute block is " + std::to_string(attr_b.size()) + " bytes for " +
                 std::to_string(meta_.voxel_count) + " voxels");
    top_attr_ = std::move(attr_b);
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

  // The bricks file: header, size, same store.
  const std::string& bpath = bricks->path();
  if (bricks->size() < kFileHeaderSize)
    return CorruptionError("'" + bpath + "' is " + std::to_string(bricks->size()) +
                           " bytes: truncated (the index expects " +
                           std::to_string(f.brick_file_size) + ")");
  VOX_RETURN_IF_ERROR(bricks->Read(0, kFileHeaderSize, head));
  VOX_ASSIGN_OR_RETURN(FileHeader bh, DecodeFileHeader(head, kBrickMagic, bpath));
  if (bh.store_id != ih.store_id)
    return CorruptionError("'" + bpath + "' belongs to a different store than '" + ipath + "'");
  if (bricks->size() != f.brick_file_size)
    return CorruptionError("'" + bpath + "' is " + std::to_string(bricks->size()) +
                           " bytes; the index expects " + std::to_string(f.brick_file_size) +
                           (bricks->size() < f.brick_file_size ? " (truncated)" : ""));

  // The brick table: every record inside the brick file, sizes consistent.
  if (table_b.size() != meta_.brick_count * kTableEntrySize)
    return bad("brick table is " + std::to_string(table_b.size()) + " bytes for " +
               std::to_string(meta_.brick_count) + " bricks");
  table_.resize(meta_.brick_count);
  uint64_t voxels = 0;
  const uint64_t bsize = f.brick_file_size;
  const uint64_t brick_grid = uint64_t(1) << meta_.brick_level;
  const size_t attr_bytes = AttrBytesPerVoxel(flags_);
  for (size_t i = 0; i < table_.size(); ++i) {
    BrickEntry e = DecodeBrickEntry(table_b.data() + i * kTableEntrySize);
    auto row = [&](const std::string& m) { return bad("brick " + std::to_string(i) + " " + m); };
    if (e.offset < kFileHeaderSize || e.offset > bsize ||
        uint64_t(e.stored_size) + kTrailerSize > bsize - e.offset)
      return row("record [" + std::to_string(e.offset) + ", +" + std::to_string(e.stored_size) +
                 ") lies outside '" + bpath + "' (" + std::to_string(bsize) + " bytes)");
    if (e.codec != kCodecZstd && e.codec != kCodecRaw)
      return row("has unknown codec " + std::to_string(e.codec));
    if (e.raw_size > kMaxBrickRawBytes ||
        e.raw_size != kBrickHeaderSize + uint64_t(e.num_cells) + uint64_t(e.voxel_count) * attr_bytes)
      return row("sizes are inconsistent (" + std::to_string(e.raw_size) + " bytes, " +
                 std::to_string(e.num_cells) + " cells, " + std::to_string(e.voxel_count) +
                 " voxels)");
    if (e.num_cells == 0 || e.voxel_count == 0 || e.num_cells > MaxCells(depth_, e.voxel_count))
      return row("has " + std::to_string(e.num_cells) + " cells for " +
                 std::to_string(e.voxel_count) + " voxels: impossible at depth " +
                 std::to_string(depth_));
    if (e.x >= brick_grid || e.y >= brick_grid || e.z >= brick_grid)
      return row("coordinate lies outside the brick grid");
    voxels += e.voxel_count;
    table_[i] = e;
  }
  if (!top_only && voxels != meta_.voxel_count)
    return bad("bricks hold " + std::to_string(voxels) + " voxels, the metadata says " +
               std::to_string(meta_.voxel_count));
  bricks_ = std::move(bricks);
  windows_ = std::make_unique<RecordWindows>(bricks_.get(), table_);
  SetCacheCapacity(options_.cache_bytes);
  return OkStatus();
}

}  // namespace

StatusOr<std::unique_ptr<Store>> OpenStoreFromFiles(const std::string& dir,
                                                    std::unique_ptr<RandomAccessFile> index,
                                                    std::unique_ptr<RandomAccessFile> bricks,
                                                    const OpenOptions& options) {
  auto store = std::make_unique<StoreImpl>(dir, options);
  VOX_RETURN_IF_ERROR(store->Load(std::move(index), std::move(bricks)));
  return std::unique_ptr<Store>(std::move(store));
}

const std::vector<BrickEntry>& BrickTable(const Store& store) {
  return static_cast<const StoreImpl&>(store).table();
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

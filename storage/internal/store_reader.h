// The store reader behind Store::Open (storage/store.cpp): the resident
// top, the brick table, the page cache of decoded bricks, record windows,
// and the background reads of Prefetch (storage/store_prefetch.cpp).
// Private to storage.
//
// Thread safety: as Store (storage/store.h).
#ifndef VOX_STORAGE_INTERNAL_STORE_READER_H_
#define VOX_STORAGE_INTERNAL_STORE_READER_H_

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <new>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "core/util/file.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/internal/record_windows.h"
#include "storage/internal/table_pages.h"
#include "core/util/memory_budget.h"
#include "storage/buffer_pool.h"
#include "storage/page_cache.h"
#include "storage/store.h"

namespace vox::storage_internal {

class StoreImpl : public Store {
 public:
  StoreImpl(std::string dir, const OpenOptions& options)
      : dir_(std::move(dir)), options_(options), cache_(options.cache_bytes),
        reclaimer_(RegisterBrickReclaimer([this] { return uint64_t(cache_.EvictUnpinned()); })) {}
  ~StoreImpl() override {
    UnregisterBrickReclaimer(reclaimer_);
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
    return BrickView{b->CellData(), b->CellCount(), std::move(b), data};
  }

  StatusOr<BrickView> FetchBrickIfReady(uint32_t id) override {
    std::shared_ptr<const DecodedBrick> b = id < table_->size() ? cache_.Peek(id) : nullptr;
    if (!b) {
      if (id >= table_->size()) return Get(id).status();  // the error naming the bad id
      return UnavailableError("brick " + std::to_string(id) + " of store '" + dir_ +
                              "' is not in memory");
    }
    const DecodedBrick* data = b.get();
    return BrickView{b->CellData(), b->CellCount(), std::move(b), data};
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

  bool PinnedDensity(const Hit& hit, float* density, int* uniform_levels) override {
    const auto* b = static_cast<const DecodedBrick*>(hit.brick_data);
    if (b == nullptr || hit.brick == kNoBrick || hit.payload >= b->voxel_count) return false;
    if (b->uniform_density >= 0) {
      *density = b->uniform_density;
      *uniform_levels = depth_;
    } else {
      const uint8_t* at = b->DensityPlace(hit.payload);
      if (at == nullptr) {
        *density = b->common_density;
      } else {
        *density = std::bit_cast<float>(uint32_t(at[0]) | uint32_t(at[1]) << 8 | uint32_t(at[2]) << 16 |
                                        uint32_t(at[3]) << 24);
        // The densities of the cache lines before and after this voxel's:
        // a walk's next voxels are its neighbours in the brick's octree
        // order, on either side as the ray runs (a fog's walk otherwise
        // waits on memory for a good share of its time).
        // (addresses as integers: the lines may lie outside the array,
        // which a prefetch may name but a pointer may not)
        const uintptr_t line = reinterpret_cast<uintptr_t>(at);
        __builtin_prefetch(reinterpret_cast<const void*>(line - 64));
        __builtin_prefetch(reinterpret_cast<const void*>(line + 64));
      }
      *uniform_levels = b->UniformLevelsOf(hit.payload);
    }
    return true;
  }

  CacheStats cache_stats() const override {
    PageCacheCounters c = cache_.counters();
    CacheStats s;
    s.hits = c.hits;
    s.misses = c.misses;
    s.evictions = c.evictions;
    s.brick_file_bytes = bricks_ ? bricks_->size() : 0;
    s.bytes_decompressed = bytes_decompressed_.load(std::memory_order_relaxed);
    s.bytes_resident = c.charge + (windows_ ? windows_->charge() : 0);
    s.capacity = c.capacity + (windows_ ? windows_->capacity() : 0);
    s.prefetched = c.prefetched;
    s.prefetch_hits = c.prefetch_hits;
    s.prefetch_dropped = pf_dropped_.load(std::memory_order_relaxed);
    s.prefetch_failed = pf_failed_.load(std::memory_order_relaxed);
    s.bytes_read = bytes_read_.load(std::memory_order_relaxed) +
                   (windows_ ? windows_->bytes_read() : 0);
    s.table_pages_read = table_ ? table_->pages_read() : 0;
    s.table_bytes_read = table_ ? table_->bytes_read() : 0;
    s.windows_read = windows_ ? windows_->windows_read() : 0;
    s.window_bytes = windows_ ? windows_->window_bytes() : 0;
    s.given_to_heap = given_to_heap_.load(std::memory_order_relaxed);
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
    return top_.size() * sizeof(CompactCell) + top_attr_.size() + table_->resident_bytes();
  }

  // From the table's summary (the 1.2 metadata's, or computed at open): the
  // largest cells and voxels may come from two bricks, so max_decoded bounds
  // the largest brick's charge from above.
  BrickSizes brick_sizes() const override {
    BrickSizes z;
    const uint64_t n = table_->size();
    if (n == 0) return z;
    const TableSummary& t = table_->summary();
    BrickEntry big;
    big.num_cells = t.max_num_cells;
    big.voxel_count = t.max_voxel_count;
    z.max_decoded = DecodedCharge(big);
    z.max_stored = uint64_t(t.max_stored_size) + kTrailerSize;
    z.mean_decoded = sizeof(DecodedBrick) + DecodedBrick::kOverheadBytes +
                     t.sum_num_cells * sizeof(CompactCell) / n +
                     meta_.voxel_count * AttrBytesPerVoxel(flags_) / n;
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
    budget_capacity_.store(bytes - windows);
  }

  const TablePages& table() const { return *table_; }
  // The decoded bricks' part of the capacity SetCacheCapacity last set (the
  // rest is the record windows').
  uint64_t decoded_capacity() const { return budget_capacity_.load(); }

 private:
  // Load's check of the top octree (`top_b`) and the top attributes
  // (`attr_b`) against meta_, into top_ and top_attr_.
  Status LoadTop(const std::vector<uint8_t>& top_b, std::vector<uint8_t> attr_b,
                 uint64_t table_size, const std::string& ipath);

  StatusOr<std::shared_ptr<const DecodedBrick>> Get(uint32_t id) {
    if (id >= table_->size())
      return InvalidArgumentError("brick " + std::to_string(id) + " does not exist (store '" +
                                  dir_ + "' has " + std::to_string(table_->size()) + " bricks)");
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
      AbsorbHeapGrowth(charge);
      return std::make_pair(std::shared_ptr<const DecodedBrick>(std::move(*b)), charge);
    });
  }

  // Gives up brick cache capacity when the process's anonymous memory has
  // grown past what its budget planned (HeapWatch: memory the allocator
  // keeps between live blocks as the cache churns), down to a quarter of
  // the capacity the budget set. `loaded`: the bytes just decoded.
  void AbsorbHeapGrowth(uint64_t loaded) {
    const uint64_t give = HeapWatch::Process().Loaded(loaded);
    if (give == 0) return;
    std::lock_guard<std::mutex> lock(give_mu_);  // rare: one shrink at a time
    const uint64_t now = cache_.capacity(), floor = budget_capacity_.load() / 4;
    const uint64_t next = now > floor + give ? now - give : std::min(now, floor);
    cache_.SetCapacity(size_t(next));
    given_to_heap_.fetch_add(now - next, std::memory_order_relaxed);
  }

  // The most the cache charges for the brick of entry `e` once decoded
  // (DecodedBrick::MaxCharge: its arrays in whole pool blocks).
  uint64_t DecodedCharge(const BrickEntry& e) const {
    return DecodedBrick::MaxCharge(e.num_cells, uint64_t(e.voxel_count) * AttrBytesPerVoxel(flags_),
                                   (flags_ & kAttrDensity) ? e.voxel_count : 0);
  }
  // A brick is decoded only if it fits what the budget gives one brick: the
  // brick cache's capacity, or kMinBrickAllowance if that is smaller (a tiny
  // cache still decodes ordinary bricks and evicts them at once). Checked
  // from the table row, before anything is allocated or read.
  static constexpr uint64_t kMinBrickAllowance = uint64_t(4) << 20;
  Status CheckBrickFits(uint32_t id, const BrickEntry& e) const;
  StatusOr<std::shared_ptr<DecodedBrick>> LoadBrick(uint32_t id);
  // Checks and decodes brick `id` (table row `e`) from its record
  // (stored_size + trailer bytes).
  StatusOr<std::shared_ptr<DecodedBrick>> DecodeRecord(uint32_t id, const BrickEntry& e,
                                                       const uint8_t* record);
  // A run of bricks neighbouring in the brick file, in file order, read with
  // one pread.
  struct Run {
    std::vector<uint32_t> ids;
    std::vector<BrickEntry> rows;  // their table rows
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
    return b.AttributesOf(payload);
  }

  const std::string dir_;
  const OpenOptions options_;
  StoreMeta meta_;
  int depth_ = 0;
  uint64_t store_id_ = 0;
  uint8_t flags_ = 0;
  std::vector<CompactCell> top_;  // traversal form (the file holds the build form)
  std::vector<uint8_t> top_attr_;  // value arrays (brick_codec.h)
  std::unique_ptr<RandomAccessFile> index_;  // the table's pages are read from it
  std::unique_ptr<TablePages> table_;        // set by Load
  std::unique_ptr<RandomAccessFile> bricks_;
  std::unique_ptr<RecordWindows> windows_;  // reads records; set by Load
  ShardedPageCache<DecodedBrick> cache_;
  // The brick pool asks the cache for room through it (storage/buffer_pool.h).
  const uint64_t reclaimer_;
  std::atomic<uint64_t> bytes_decompressed_{0};
  std::atomic<uint64_t> budget_capacity_{0};  // the brick cache's bytes as SetCacheCapacity set them
  std::atomic<uint64_t> given_to_heap_{0};    // of those, given up by AbsorbHeapGrowth
  std::mutex give_mu_;
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


}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_STORE_READER_H_

// vox::PageCache<V> and vox::ShardedPageCache<V>: a thread-safe LRU cache of immutable values charged in
// bytes against a capacity, with single-flight loading: concurrent askers of
// a missing key wait for one load instead of each loading it. A returned
// shared_ptr pins its value: eviction drops only the cache's reference, so
// a pinned value stays valid (and outside the budget) until released.
// Values inserted ahead of need (InsertPrefetched) are marked until first
// asked for, so prefetch hits and prefetched bytes not yet used are known.
//
// Thread safety: every member is thread-safe. The loader runs without the
// cache's lock held and must not call back into the same key.
#ifndef VOX_STORAGE_PAGE_CACHE_H_
#define VOX_STORAGE_PAGE_CACHE_H_

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/util/status.h"

namespace vox {

struct PageCacheCounters {
  uint64_t hits = 0;       // found cached, or joined another thread's load
  uint64_t misses = 0;     // loads run (one per miss, whatever the number of askers)
  uint64_t joined = 0;     // asks that waited for another thread's load (also in hits)
  uint64_t evictions = 0;
  uint64_t charge = 0;     // bytes held now
  uint64_t capacity = 0;
  uint64_t entries = 0;
  uint64_t prefetched = 0;       // values inserted by InsertPrefetched
  uint64_t prefetch_hits = 0;    // of those, asked for before eviction
  uint64_t prefetch_unused = 0;  // bytes of prefetched values not yet asked for
};

template <class V>
class PageCache {
 public:
  using Value = std::shared_ptr<const V>;

  explicit PageCache(size_t capacity) : capacity_(capacity) {}
  PageCache(const PageCache&) = delete;
  PageCache& operator=(const PageCache&) = delete;

  // The value for `key`: cached, or produced by `load()` -> StatusOr<std::pair<
  // Value, size_t charge>>, run once however many threads ask at once. A
  // failed load is not cached; every waiter gets its Status.
  template <class Loader>
  StatusOr<Value> GetOrLoad(uint64_t key, Loader&& load) {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      if (Value v = LookupLocked(key)) return v;
      auto fit = flights_.find(key);
      if (fit == flights_.end()) break;
      std::shared_ptr<Flight> f = fit->second;
      ++f->waiters;
      cv_.wait(lock, [&] { return f->done; });
      if (!f->status.ok()) {
        ++counters_.hits;
        ++counters_.joined;
        return f->status;
      }
      if (f->value) {
        ++counters_.hits;
        ++counters_.joined;
        return f->value;
      }
      // A claim released without a value (a prefetch that failed): load it here.
    }
    ++counters_.misses;
    auto flight = std::make_shared<Flight>();
    flights_.emplace(key, flight);
    lock.unlock();
    auto loaded = load();
    lock.lock();
    flight->done = true;
    flights_.erase(key);
    if (!loaded.ok()) {
      flight->status = loaded.status();
      cv_.notify_all();
      return loaded.status();
    }
    flight->value = loaded->first;
    InsertLocked(key, loaded->first, loaded->second);
    cv_.notify_all();
    return flight->value;
  }

  // Claims `key` for a load made outside GetOrLoad (a prefetch reading many
  // values at once): true when `key` was neither cached nor being loaded.
  // Until FinishClaim, askers of `key` wait for it instead of loading it
  // again. Every successful Claim must be followed by one FinishClaim.
  bool Claim(uint64_t key) {
    std::lock_guard<std::mutex> lock(mu_);
    if (map_.count(key) != 0 || flights_.count(key) != 0) return false;
    flights_.emplace(key, std::make_shared<Flight>());
    return true;
  }

  // Ends a claim. A non-null `value` is cached, marked prefetched unless
  // someone is already waiting for it (then it counts as a prefetch hit); a
  // null one releases the waiters to load `key` themselves.
  void FinishClaim(uint64_t key, Value value, size_t charge) {
    std::lock_guard<std::mutex> lock(mu_);
    auto fit = flights_.find(key);
    if (fit == flights_.end()) return;
    std::shared_ptr<Flight> f = fit->second;
    flights_.erase(fit);
    f->done = true;
    if (value) {
      f->value = value;
      ++counters_.prefetched;
      if (f->waiters > 0) ++counters_.prefetch_hits;
      InsertLocked(key, std::move(value), charge, /*prefetched=*/f->waiters == 0);
    }
    cv_.notify_all();
  }

  // The cached value (counting a hit), or null (counting nothing: no load
  // follows).
  Value Peek(uint64_t key) {
    std::lock_guard<std::mutex> lock(mu_);
    return LookupLocked(key);
  }

  // The cached value, or null. Counts a hit or a miss.
  Value Lookup(uint64_t key) {
    std::lock_guard<std::mutex> lock(mu_);
    Value v = LookupLocked(key);
    if (!v) ++counters_.misses;
    return v;
  }

  // Caches `value` (replacing any entry for `key`) and evicts least recently
  // used entries until the total charge is within capacity.
  void Insert(uint64_t key, Value value, size_t charge) {
    std::lock_guard<std::mutex> lock(mu_);
    InsertLocked(key, std::move(value), charge);
  }

  // Caches a value loaded ahead of need, unless `key` is cached or being
  // loaded already (a loader's value is fresher). Returns whether inserted.
  bool InsertPrefetched(uint64_t key, Value value, size_t charge) {
    std::lock_guard<std::mutex> lock(mu_);
    if (map_.count(key) != 0 || flights_.count(key) != 0) return false;
    InsertLocked(key, std::move(value), charge, /*prefetched=*/true);
    ++counters_.prefetched;
    return true;
  }

  // Whether `key` is cached or being loaded; counts nothing, moves nothing.
  bool Contains(uint64_t key) const {
    std::lock_guard<std::mutex> lock(mu_);
    return map_.count(key) != 0 || flights_.count(key) != 0;
  }

  void Erase(uint64_t key) {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = map_.find(key);
    if (it != map_.end()) RemoveLocked(it);
  }

  // Bytes of prefetched values not yet asked for.
  size_t PrefetchUnused() const {
    std::lock_guard<std::mutex> lock(mu_);
    return prefetch_unused_;
  }

  // Evicts the least recently used value that nothing outside the cache
  // holds (unpinned: dropping it frees it) and returns its charge; 0 when
  // every cached value is pinned or the cache is empty. Pinned values are
  // skipped, not moved. For a memory pool that needs room
  // (storage/buffer_pool.h); counted as an eviction.
  size_t EvictUnpinned() {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto k = lru_.rbegin(); k != lru_.rend(); ++k) {
      auto it = map_.find(*k);
      // A value only the cache holds gains a reference only under mu_.
      if (it->second.value.use_count() != 1) continue;
      const size_t charge = it->second.charge;
      RemoveLocked(it);
      ++counters_.evictions;
      return charge;
    }
    return 0;
  }

  size_t TotalCharge() const {
    std::lock_guard<std::mutex> lock(mu_);
    return usage_;
  }
  size_t capacity() const {
    std::lock_guard<std::mutex> lock(mu_);
    return capacity_;
  }
  // Changes the capacity, evicting least recently used entries down to it.
  void SetCapacity(size_t capacity) {
    std::lock_guard<std::mutex> lock(mu_);
    capacity_ = capacity;
    EvictLocked();
  }

  PageCacheCounters counters() const {
    std::lock_guard<std::mutex> lock(mu_);
    PageCacheCounters c = counters_;
    c.charge = usage_;
    c.capacity = capacity_;
    c.entries = map_.size();
    c.prefetch_unused = prefetch_unused_;
    return c;
  }

 private:
  struct Entry {
    Value value;
    size_t charge = 0;
    std::list<uint64_t>::iterator lru;
    bool prefetched = false;  // inserted ahead of need and not asked for yet
  };
  struct Flight {
    bool done = false;
    int waiters = 0;
    Status status;
    Value value;
  };

  Value LookupLocked(uint64_t key) {
    auto it = map_.find(key);
    if (it == map_.end()) return nullptr;
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    ++counters_.hits;
    if (it->second.prefetched) {
      it->second.prefetched = false;
      prefetch_unused_ -= it->second.charge;
      ++counters_.prefetch_hits;
    }
    return it->second.value;
  }

  void RemoveLocked(typename std::unordered_map<uint64_t, Entry>::iterator it) {
    usage_ -= it->second.charge;
    if (it->second.prefetched) prefetch_unused_ -= it->second.charge;
    lru_.erase(it->second.lru);
    map_.erase(it);
  }

  void InsertLocked(uint64_t key, Value value, size_t charge, bool prefetched = false) {
    auto it = map_.find(key);
    if (it != map_.end()) RemoveLocked(it);
    lru_.push_front(key);
    map_.emplace(key, Entry{std::move(value), charge, lru_.begin(), prefetched});
    usage_ += charge;
    if (prefetched) prefetch_unused_ += charge;
    EvictLocked();
  }

  void EvictLocked() {
    while (usage_ > capacity_ && !lru_.empty()) {
      RemoveLocked(map_.find(lru_.back()));
      ++counters_.evictions;
    }
  }

  size_t capacity_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::unordered_map<uint64_t, Entry> map_;
  std::list<uint64_t> lru_;  // front: most recently used
  std::unordered_map<uint64_t, std::shared_ptr<Flight>> flights_;
  size_t usage_ = 0;
  size_t prefetch_unused_ = 0;
  PageCacheCounters counters_;
};

// PageCache split into independent shards by key, each with an equal part of
// the capacity, so threads working on different keys rarely share a lock
// (LevelDB's ShardedLRUCache). The total charge never exceeds the capacity;
// LRU order and single flight hold within each shard. Thread-safe.
template <class V>
class ShardedPageCache {
 public:
  using Value = typename PageCache<V>::Value;

  // `shards` 0 picks as many as keep each shard at least `min_shard_bytes`,
  // at most 16.
  explicit ShardedPageCache(size_t capacity, size_t shards = 0,
                            size_t min_shard_bytes = size_t(4) << 20)
      : capacity_(capacity) {
    if (shards == 0) shards = std::clamp<size_t>(capacity / min_shard_bytes, 1, 16);
    for (size_t i = 0; i < shards; ++i) {
      size_t part = capacity / shards + (i < capacity % shards ? 1 : 0);
      shards_.push_back(std::make_unique<PageCache<V>>(part));
    }
  }

  template <class Loader>
  StatusOr<Value> GetOrLoad(uint64_t key, Loader&& load) {
    return Shard(key).GetOrLoad(key, std::forward<Loader>(load));
  }
  Value Lookup(uint64_t key) { return Shard(key).Lookup(key); }
  Value Peek(uint64_t key) { return Shard(key).Peek(key); }
  void Insert(uint64_t key, Value value, size_t charge) {
    Shard(key).Insert(key, std::move(value), charge);
  }
  void Erase(uint64_t key) { Shard(key).Erase(key); }
  bool InsertPrefetched(uint64_t key, Value value, size_t charge) {
    return Shard(key).InsertPrefetched(key, std::move(value), charge);
  }
  bool Claim(uint64_t key) { return Shard(key).Claim(key); }
  void FinishClaim(uint64_t key, Value value, size_t charge) {
    Shard(key).FinishClaim(key, std::move(value), charge);
  }
  bool Contains(uint64_t key) const { return Shard(key).Contains(key); }
  size_t PrefetchUnused() const {
    size_t t = 0;
    for (const auto& s : shards_) t += s->PrefetchUnused();
    return t;
  }

  // PageCache::EvictUnpinned over the shards, each asked in turn from
  // where the last call stopped; 0 when no shard holds an unpinned value.
  size_t EvictUnpinned() {
    const size_t n = shards_.size(), start = evict_turn_.fetch_add(1, std::memory_order_relaxed);
    for (size_t i = 0; i < n; ++i)
      if (size_t freed = shards_[(start + i) % n]->EvictUnpinned()) return freed;
    return 0;
  }

  size_t TotalCharge() const {
    size_t t = 0;
    for (const auto& s : shards_) t += s->TotalCharge();
    return t;
  }
  size_t capacity() const { return capacity_.load(std::memory_order_relaxed); }
  size_t num_shards() const { return shards_.size(); }
  // Changes the total capacity (split evenly over the shards, whose number
  // stays as chosen at construction), evicting down to it.
  void SetCapacity(size_t capacity) {
    capacity_.store(capacity, std::memory_order_relaxed);
    const size_t n = shards_.size();
    for (size_t i = 0; i < n; ++i) shards_[i]->SetCapacity(capacity / n + (i < capacity % n ? 1 : 0));
  }

  PageCacheCounters counters() const {
    PageCacheCounters t;
    for (const auto& s : shards_) {
      PageCacheCounters c = s->counters();
      t.hits += c.hits;
      t.misses += c.misses;
      t.joined += c.joined;
      t.evictions += c.evictions;
      t.charge += c.charge;
      t.entries += c.entries;
      t.prefetched += c.prefetched;
      t.prefetch_hits += c.prefetch_hits;
      t.prefetch_unused += c.prefetch_unused;
    }
    t.capacity = capacity();
    return t;
  }

 private:
  PageCache<V>& Shard(uint64_t key) const {
    // Neighbouring keys (bricks close in Morton order) land in different shards.
    uint64_t h = key * 0x9E3779B97F4A7C15ull;
    return *shards_[(h >> 32) % shards_.size()];
  }

  std::atomic<size_t> capacity_;
  std::atomic<size_t> evict_turn_{0};
  std::vector<std::unique_ptr<PageCache<V>>> shards_;
};

}  // namespace vox

#endif  // VOX_STORAGE_PAGE_CACHE_H_

#include "storage/buffer_pool.h"

#include <sys/mman.h>

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <new>
#include <shared_mutex>
#include <sstream>

namespace vox {

StatusOr<std::unique_ptr<BufferPool>> BufferPool::Create(uint64_t bytes) {
  const uint64_t size = bytes / kMinBlock * kMinBlock;
  if (size == 0) return InvalidArgumentError("a buffer pool needs at least " + std::to_string(kMinBlock) + " bytes");
  // The blocks' states follow the blocks in the same mapping: the kernel
  // zeroes their pages as they are first touched, so a pool of gigabytes
  // costs nothing at start for the byte per kMinBlock it may need.
  void* p = mmap(nullptr, size + StateBytes(size), PROT_READ | PROT_WRITE,
                 MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (p == MAP_FAILED)
    return ResourceExhaustedError("cannot map a brick pool of " + std::to_string(size >> 20) +
                                  " MiB (the address space limit, ulimit -v?)");
  return std::unique_ptr<BufferPool>(new BufferPool(reinterpret_cast<uintptr_t>(p), size));
}

BufferPool::BufferPool(uintptr_t base, uint64_t size)
    : base_(base), size_(size), state_(reinterpret_cast<uint8_t*>(base + size)) {
  while ((kMinBlock << (max_order_ + 1)) <= size_) ++max_order_;
  heads_.assign(size_t(max_order_) + 1, kNone);
  // The mapping as blocks of decreasing powers of two: each lies at a
  // multiple of its size, and the buddy of a block at the tail is past the
  // end, so it never merges out of the pool.
  uint64_t off = 0;
  for (int k = max_order_; k >= 0; --k)
    while (off + (kMinBlock << k) <= size_) {
      Push(off, k);
      off += kMinBlock << k;
    }
}

BufferPool::~BufferPool() {
  if (!retired_) munmap(reinterpret_cast<void*>(base_), size_ + StateBytes(size_));
}

uint64_t BufferPool::StateBytes(uint64_t size) {
  const uint64_t page = 4096;
  return ((size >> kMinShift) + page - 1) / page * page;
}

size_t BufferPool::BlockSize(size_t n) { return n <= kMinBlock ? kMinBlock : std::bit_ceil(n); }

void BufferPool::Push(uint64_t off, int order) {
  Links* l = At(off);
  l->prev = kNone;
  l->next = heads_[order];
  if (l->next != kNone) At(l->next)->prev = off;
  heads_[order] = off;
  state_[off >> kMinShift] = uint8_t(kFree | order);
}

void BufferPool::Unlink(uint64_t off, int order) {
  Links* l = At(off);
  if (l->prev != kNone) At(l->prev)->next = l->next;
  else heads_[order] = l->next;
  if (l->next != kNone) At(l->next)->prev = l->prev;
  state_[off >> kMinShift] = uint8_t(order);
}

void* BufferPool::Allocate(size_t n) {
  const size_t bs = BlockSize(n);
  const int want = std::countr_zero(bs) - kMinShift;
  uint64_t off;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (retired_ || want > max_order_) return nullptr;
    int k = want;
    while (k <= max_order_ && heads_[k] == kNone) ++k;
    if (k > max_order_) return nullptr;
    off = heads_[k];
    Unlink(off, k);
    while (k > want) {  // split, keeping the lower half, freeing the upper
      --k;
      Push(off + (kMinBlock << k), k);
    }
    state_[off >> kMinShift] = uint8_t(want);
    in_use_ += bs;
    peak_ = std::max(peak_, in_use_);
  }
  PopulateForWrite(base_ + off, n);
  return reinterpret_cast<void*>(base_ + off);
}

void BufferPool::PopulateForWrite(uintptr_t at, size_t n) {
#ifdef MADV_POPULATE_WRITE
  // The pages the caller is about to write, made resident in one call: the
  // kernel then zeroes and maps them in one pass instead of taking a page
  // fault per 4 KiB as they are first written. Pages already resident cost
  // a table walk; kernels without the advice (before Linux 5.14) refuse it,
  // and the pages fault in as before.
  constexpr uintptr_t kPage = 4096;
  const uintptr_t lo = at & ~(kPage - 1), hi = (at + n + kPage - 1) & ~(kPage - 1);
  if (n >= kPopulateMin) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_POPULATE_WRITE);
#else
  (void)at;
  (void)n;
#endif
}

void BufferPool::Free(void* p) {
  uint64_t off = reinterpret_cast<uintptr_t>(p) - base_;
  std::lock_guard<std::mutex> lock(mu_);
  int k = state_[off >> kMinShift] & ~kFree;
  in_use_ -= kMinBlock << k;
  while (k < max_order_) {
    const uint64_t buddy = off ^ (kMinBlock << k);
    if (buddy + (kMinBlock << k) > size_ || state_[buddy >> kMinShift] != uint8_t(kFree | k)) break;
    Unlink(buddy, k);
    state_[buddy >> kMinShift] = 0;
    off = std::min(off, buddy);
    ++k;
  }
  Push(off, k);
}

bool BufferPool::Retire() {
  std::lock_guard<std::mutex> lock(mu_);
  if (retired_) return true;
  if (in_use_ != 0) return false;
  retired_ = true;
  munmap(reinterpret_cast<void*>(base_), size_ + StateBytes(size_));
  return true;
}

uint64_t BufferPool::in_use() const {
  std::lock_guard<std::mutex> lock(mu_);
  return in_use_;
}

uint64_t BufferPool::peak_in_use() const {
  std::lock_guard<std::mutex> lock(mu_);
  return peak_;
}

namespace {

// The current brick pool. Pools replaced are retired (unmapped) but never
// deleted, so a reader racing with a replacement reads a live object.
std::atomic<BufferPool*> g_pool{nullptr};
std::mutex g_reserve_mu;
std::atomic<uint64_t> g_overflows{0}, g_overflow_bytes{0}, g_reclaimed{0}, g_reclaimed_bytes{0};

// The registered reclaimers. Allocators call them under the shared lock;
// unregistering takes it exclusively, so it waits for calls in progress.
struct Reclaimers {
  std::shared_mutex mu;
  uint64_t next_id = 1;
  std::vector<std::pair<uint64_t, BrickReclaimer>> list;
  std::atomic<size_t> turn{0};  // where the next round starts, so no cache is always first
};

Reclaimers& TheReclaimers() {
  static auto* r = new Reclaimers();  // outlives every store
  return *r;
}

// Evicts unpinned bricks until `pool` has a block for `n` bytes; that block,
// or null when every reclaimer is out of unpinned bricks.
void* ReclaimAndAllocate(BufferPool* pool, size_t n) {
  Reclaimers& r = TheReclaimers();
  std::shared_lock<std::shared_mutex> lock(r.mu);
  const size_t count = r.list.size();
  if (count == 0) return nullptr;
  size_t i = r.turn.fetch_add(1, std::memory_order_relaxed);
  for (size_t idle = 0; idle < count; ++i) {
    const uint64_t freed = r.list[i % count].second();
    if (freed == 0) {
      ++idle;
      continue;
    }
    idle = 0;
    g_reclaimed.fetch_add(1, std::memory_order_relaxed);
    g_reclaimed_bytes.fetch_add(freed, std::memory_order_relaxed);
    if (void* b = pool->Allocate(n)) return b;
  }
  return pool->Allocate(n);  // another thread may have freed a block meanwhile
}

std::vector<std::unique_ptr<BufferPool>>& Pools() {
  static auto* pools = new std::vector<std::unique_ptr<BufferPool>>();  // outlives every brick
  return *pools;
}

}  // namespace

Status ReserveBrickPool(uint64_t bytes) {
  // VOX_BRICK_POOL=0: no pool, bricks on the heap (to measure what the pool costs).
  static const bool off = [] {
    const char* e = std::getenv("VOX_BRICK_POOL");
    return e != nullptr && std::string(e) == "0";
  }();
  if (off) return OkStatus();
  std::lock_guard<std::mutex> lock(g_reserve_mu);
  BufferPool* cur = g_pool.load();
  if (cur != nullptr && cur->capacity() == bytes / BufferPool::kMinBlock * BufferPool::kMinBlock)
    return OkStatus();
  if (cur != nullptr && !cur->Retire()) return OkStatus();  // bricks still live in it: keep it
  g_pool.store(nullptr);
  VOX_ASSIGN_OR_RETURN(auto pool, BufferPool::Create(bytes));
  g_pool.store(pool.get());
  Pools().push_back(std::move(pool));
  return OkStatus();
}

BrickPoolStats ReadBrickPoolStats() {
  BrickPoolStats s;
  if (BufferPool* p = g_pool.load()) {
    s.capacity = p->capacity();
    s.in_use = p->in_use();
    s.peak_in_use = p->peak_in_use();
  }
  s.overflows = g_overflows.load(std::memory_order_relaxed);
  s.overflow_bytes = g_overflow_bytes.load(std::memory_order_relaxed);
  s.reclaimed = g_reclaimed.load(std::memory_order_relaxed);
  s.reclaimed_bytes = g_reclaimed_bytes.load(std::memory_order_relaxed);
  return s;
}

std::string BrickPoolStats::ToJson() const {
  std::ostringstream o;
  o << "{\"capacity\": " << capacity << ", \"in_use\": " << in_use << ", \"peak_in_use\": " << peak_in_use
    << ", \"overflows\": " << overflows << ", \"overflow_bytes\": " << overflow_bytes
    << ", \"reclaimed\": " << reclaimed << ", \"reclaimed_bytes\": " << reclaimed_bytes << "}";
  return o.str();
}

void* BrickAllocate(size_t n) {
  if (BufferPool* p = g_pool.load(std::memory_order_acquire)) {
    if (void* b = p->Allocate(n)) return b;
    if (void* b = ReclaimAndAllocate(p, n)) return b;
    g_overflows.fetch_add(1, std::memory_order_relaxed);
    g_overflow_bytes.fetch_add(n, std::memory_order_relaxed);
  }
  void* b = std::malloc(n == 0 ? 1 : n);
  if (b == nullptr) throw std::bad_alloc();
  return b;
}

uint64_t RegisterBrickReclaimer(BrickReclaimer reclaim) {
  Reclaimers& r = TheReclaimers();
  std::unique_lock<std::shared_mutex> lock(r.mu);
  const uint64_t id = r.next_id++;
  r.list.emplace_back(id, std::move(reclaim));
  return id;
}

void UnregisterBrickReclaimer(uint64_t id) {
  Reclaimers& r = TheReclaimers();
  std::unique_lock<std::shared_mutex> lock(r.mu);
  std::erase_if(r.list, [id](const auto& e) { return e.first == id; });
}

void BrickFree(void* p) {
  if (p == nullptr) return;
  BufferPool* pool = g_pool.load(std::memory_order_acquire);
  if (pool != nullptr && pool->Owns(p)) pool->Free(p);
  else std::free(p);
}

size_t BrickBlockBytes(const void* p, size_t n) {
  BufferPool* pool = g_pool.load(std::memory_order_acquire);
  return pool != nullptr && p != nullptr && pool->Owns(p) ? BufferPool::BlockSize(n) : n;
}

}  // namespace vox

// vox::BufferPool and the process's brick pool: the memory decoded bricks
// live in, mapped once and carved into blocks, so that a brick cache that
// churns through millions of bricks of different sizes cannot fragment the
// heap under it (a database's buffer pool: PostgreSQL's shared buffers,
// DuckDB's buffer manager).
//
// A BufferPool maps its bytes once (anonymous, private; pages become
// resident as they are first written and stay so) and hands out blocks of
// power-of-two sizes from 512 bytes up, by a binary buddy allocator: a block
// freed next to its free buddy merges with it, so the pool's free space does
// not splinter as bricks of many sizes come and go. Its resident memory never
// exceeds its mapping, whatever the churn.
//
// The brick pool (ReserveBrickPool) is the one pool of the process that
// decoded bricks are allocated from (BrickAllocator): its size is the brick
// cache and the threads' pins of the memory budget (storage/store_budget.h).
// A brick that finds no free block large enough first makes room: the
// brick caches registered as reclaimers (RegisterBrickReclaimer; every
// store's cache is one) evict their least recently used unpinned bricks, one
// at a time, until the block fits (counted: BrickPoolStats::reclaimed). Only
// when nothing unpinned is left (the pool full of pinned bricks) is the
// brick allocated from the heap instead, and counted (overflows); before a
// budget reserves a pool every brick comes from the heap.
//
// Thread safety: every function and member is thread-safe.
#ifndef VOX_STORAGE_BUFFER_POOL_H_
#define VOX_STORAGE_BUFFER_POOL_H_

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "core/util/status.h"

namespace vox {

class BufferPool {
 public:
  static constexpr int kMinShift = 9;  // the smallest block: 512 bytes
  static constexpr size_t kMinBlock = size_t(1) << kMinShift;

  // Maps `bytes` rounded down to kMinBlock. Use Create (the mapping can fail).
  static StatusOr<std::unique_ptr<BufferPool>> Create(uint64_t bytes);
  ~BufferPool();
  BufferPool(const BufferPool&) = delete;
  BufferPool& operator=(const BufferPool&) = delete;

  // A block of BlockSize(n) bytes, or null when no free block is that
  // large (or the pool is retired).
  void* Allocate(size_t n);
  // Returns a block from Allocate.
  void Free(void* p);
  // Whether `p` points into the pool's mapping.
  bool Owns(const void* p) const {
    const uintptr_t a = reinterpret_cast<uintptr_t>(p);
    return a >= base_ && a < base_ + size_;
  }
  // Unmaps the pool if no block is in use (true); Allocate fails from then on.
  bool Retire();

  // The block Allocate hands out for n bytes: the next power of two, at least kMinBlock.
  static size_t BlockSize(size_t n);

  const void* base() const { return reinterpret_cast<const void*>(base_); }
  uint64_t capacity() const { return size_; }
  uint64_t in_use() const;
  uint64_t peak_in_use() const;

 private:
  BufferPool(uintptr_t base, uint64_t size);
  // Makes [at, at + n) resident for writing, where the kernel can
  // (blocks of at least kPopulateMin bytes).
  static void PopulateForWrite(uintptr_t at, size_t n);
  static constexpr size_t kPopulateMin = 8192;
  // Free-list links live in the free blocks themselves.
  struct Links {
    uint64_t next, prev;
  };
  static constexpr uint8_t kFree = 0x80;
  static constexpr uint64_t kNone = ~uint64_t(0);
  Links* At(uint64_t off) const { return reinterpret_cast<Links*>(base_ + off); }
  void Push(uint64_t off, int order);
  void Unlink(uint64_t off, int order);
  // The bytes of the per-kMinBlock states mapped after `size` bytes of blocks.
  static uint64_t StateBytes(uint64_t size);

  const uintptr_t base_;
  const uint64_t size_;
  int max_order_ = 0;
  mutable std::mutex mu_;
  bool retired_ = false;
  std::vector<uint64_t> heads_;  // per order: the first free block's offset, or kNone
  uint8_t* const state_;         // per kMinBlock: at a block's start, kFree | order, or order
  uint64_t in_use_ = 0, peak_ = 0;
};

// The process's brick pool, by ReserveBrickPool.
struct BrickPoolStats {
  uint64_t capacity = 0;       // bytes mapped (0: no pool; bricks come from the heap)
  uint64_t in_use = 0;         // bytes in blocks handed out
  uint64_t peak_in_use = 0;    // the most ever in use at once
  uint64_t overflows = 0;      // bricks' blocks that did not fit and came from the heap
  uint64_t overflow_bytes = 0;
  uint64_t reclaimed = 0;       // unpinned bricks evicted to make room for a block
  uint64_t reclaimed_bytes = 0;  // the bytes those evictions released, as their caches charged them
  std::string ToJson() const;
};

// Makes the brick pool `bytes` large; nothing with VOX_BRICK_POOL=0 in the
// environment (bricks then come from the heap: for measuring the pool). A
// pool of another size is replaced only when none of its blocks is in use
// (between frames); otherwise it is kept as it is. Errors: the mapping
// failed (ResourceExhausted, naming the size).
Status ReserveBrickPool(uint64_t bytes);
BrickPoolStats ReadBrickPoolStats();

// A reclaimer evicts one unpinned brick (the least recently used it holds)
// and returns the bytes its cache charged for it, or 0 when it holds none
// unpinned. It is called from BrickAllocate on any thread, with no lock of
// the pool held, and must not allocate bricks itself.
using BrickReclaimer = std::function<uint64_t()>;
// Returns an id for UnregisterBrickReclaimer, which must be called before
// what the reclaimer refers to is destroyed (it waits for running calls).
uint64_t RegisterBrickReclaimer(BrickReclaimer reclaim);
void UnregisterBrickReclaimer(uint64_t id);

// From the brick pool, making room by reclaiming unpinned bricks when it is
// full; from the heap when that frees no block large enough (or there is no
// pool). Throws std::bad_alloc as operator new does.
void* BrickAllocate(size_t n);
void BrickFree(void* p);
// The bytes a block of `n` bytes at `p` holds: its pool block, or n.
size_t BrickBlockBytes(const void* p, size_t n);

// A std::allocator over BrickAllocate that leaves trivially constructible
// elements uninitialised on resize (their bytes are written whole after).
template <class T>
struct BrickAllocator {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = BrickAllocator<U>;
  };
  BrickAllocator() = default;
  template <class U>
  BrickAllocator(const BrickAllocator<U>&) noexcept {}
  T* allocate(size_t n) { return static_cast<T*>(BrickAllocate(n * sizeof(T))); }
  void deallocate(T* p, size_t) noexcept { BrickFree(p); }
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  bool operator==(const BrickAllocator<U>&) const noexcept {
    return true;
  }
};

}  // namespace vox

#endif  // VOX_STORAGE_BUFFER_POOL_H_

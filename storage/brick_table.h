// vox::LendingBrickTable: one thread's table of the bricks it used last, in
// front of a shared BrickSource (a Store's cache). Bricks sit pinned in a
// direct-mapped table of 2^slot_bits slots, so a ray entering a brick a
// neighbouring ray just used takes neither the shared cache's lock, hash and
// LRU nor a reference count: the table lends its views to the thread's
// traversal (BrickSource::lends, core/octree.h). The pins hold at most
// 2^slot_bits bricks alive beyond the shared cache's budget: a memory budget
// sizes the table by bytes (SlotBitsForBytes).
//
// Thread safety: thread-compatible; one table per thread. The shared source
// must be thread-safe and outlive the table.
#ifndef VOX_STORAGE_BRICK_TABLE_H_
#define VOX_STORAGE_BRICK_TABLE_H_

#include <cstdint>
#include <vector>

#include "core/octree.h"
#include "core/util/status.h"

namespace vox {

class LendingBrickTable : public BrickSource {
 public:
  // slot_bits is clamped to 0..16 (0: one slot).
  LendingBrickTable(BrickSource* shared, int slot_bits);

  // Table size for a shared cache of `capacity` bytes: 256 slots (a 64 x 64
  // tile's rays enter a few dozen bricks; 256 was faster than 64,
  // docs/performance.md) at 1 GiB, fewer (down to 16) for smaller caches, so
  // the pins of a thread stay near 1/64 of the budget for bricks of 64 KiB.
  static int SlotBits(uint64_t capacity);
  // The most slots (a power of two, 1..256) whose pins, at `brick_bytes`
  // each (the largest brick as the cache charges it), stay within
  // `pin_bytes`: one slot when even two do not fit.
  static int SlotBitsForBytes(uint64_t pin_bytes, uint64_t brick_bytes);

  size_t num_slots() const { return slots_.size(); }

  // No-wait mode: a brick missing from the table is taken from the shared
  // source only if it is in memory there (FetchBrickIfReady); otherwise the
  // fetch fails with UnavailableError and its id is added to wanted(), for
  // the caller to have it read (Store::Prefetch) while it does other work.
  void set_no_wait(bool no_wait) { no_wait_ = no_wait; }
  bool no_wait() const { return no_wait_; }
  std::vector<uint32_t>& wanted() { return wanted_; }
  // Bricks held pinned now (at most num_slots()).
  size_t pinned() const;

  // A copy of the lent view (its pin keeps the brick alive on its own).
  StatusOr<BrickView> FetchBrick(uint32_t id) override;
  bool lends() const override { return true; }
  // Brick `id`'s view from its slot, fetched from the shared source on a
  // miss (replacing the slot's brick); nullptr with *error set when the
  // shared source fails. Valid until the next call on this table.
  const BrickView* LendBrick(uint32_t id, Status* error) override;
  const uint64_t* lend_epoch() const override { return &epoch_; }

 private:
  struct Slot {
    uint32_t id = 0;
    BrickView view;  // cells == nullptr: empty
  };
  BrickSource* shared_;
  bool no_wait_ = false;
  std::vector<uint32_t> wanted_;
  uint64_t epoch_ = 0;  // lends that replaced a slot's brick
  int shift_;  // 32 - slot bits: the slot is the hash's top bits
  std::vector<Slot> slots_;
};

}  // namespace vox

#endif  // VOX_STORAGE_BRICK_TABLE_H_

#include "storage/brick_table.h"

#include <utility>

namespace vox {

namespace {
int ClampSlotBits(int bits) { return bits < 0 ? 0 : bits > 16 ? 16 : bits; }
}  // namespace

LendingBrickTable::LendingBrickTable(BrickSource* shared, int slot_bits)
    : shared_(shared),
      shift_(32 - ClampSlotBits(slot_bits)),
      slots_(size_t(1) << ClampSlotBits(slot_bits)) {}

int LendingBrickTable::SlotBits(uint64_t capacity) {
  int bits = 4;
  while (bits < 8 && (uint64_t(1) << (bits + 1)) * (64u << 10) * 64 <= capacity) ++bits;
  return bits;
}

int LendingBrickTable::SlotBitsForBytes(uint64_t pin_bytes, uint64_t brick_bytes) {
  if (brick_bytes == 0) return 8;  // no bricks: nothing will be pinned
  int bits = 0;
  while (bits < 8 && (uint64_t(2) << bits) * brick_bytes <= pin_bytes) ++bits;
  return bits;
}

size_t LendingBrickTable::pinned() const {
  size_t n = 0;
  for (const Slot& s : slots_) n += s.view.cells != nullptr ? 1 : 0;
  return n;
}

StatusOr<BrickView> LendingBrickTable::FetchBrick(uint32_t id) {
  Status error;
  const BrickView* v = LendBrick(id, &error);
  if (v == nullptr) return error;
  return *v;
}

const BrickView* LendingBrickTable::LendBrick(uint32_t id, Status* error) {
  // Fibonacci hashing: neighbouring brick ids spread over the slots.
  Slot& s = slots_[uint64_t(id * 2654435761u) >> shift_];
  if (s.id == id && s.view.cells != nullptr) return &s.view;
  auto v = no_wait_ ? shared_->FetchBrickIfReady(id) : shared_->FetchBrick(id);
  if (!v.ok()) {
    if (no_wait_ && v.status().code() == StatusCode::kUnavailable) wanted_.push_back(id);
    *error = v.status();
    return nullptr;
  }
  if (s.view.cells != nullptr) ++epoch_;  // (the slot's brick may have been lent)
  s.id = id;
  s.view = std::move(v).value();
  return &s.view;
}

}  // namespace vox

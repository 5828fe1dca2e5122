// RecordWindows: see record_windows.h.
#include "storage/internal/record_windows.h"

#include <algorithm>
#include <string>

namespace vox::storage_internal {
namespace {

// Keys carry the window size, so windows of an earlier size (SetCapacity)
// never answer for the current one; they age out of the LRU.
uint64_t WindowKey(uint64_t w, uint64_t window) {
  return w << 6 | uint64_t(__builtin_ctzll(window));
}

}  // namespace

RecordWindows::RecordWindows(const RandomAccessFile* file, std::span<const BrickEntry> table)
    : file_(file), table_(table), order_(table.size()) {
  for (uint32_t i = 0; i < order_.size(); ++i) order_[i] = i;
  std::sort(order_.begin(), order_.end(),
            [&](uint32_t a, uint32_t b) { return table_[a].offset < table_[b].offset; });
}

uint64_t RecordWindows::ShareOf(uint64_t cache_bytes) {
  return std::min(cache_bytes / 8, kMaxCapacity);
}

void RecordWindows::SetCapacity(uint64_t bytes) {
  uint64_t w = kMaxWindow;
  while (w >= kMinWindow && w * 128 > bytes) w >>= 1;
  if (w < kMinWindow) {
    capacity_ = window_ = 0;
    cache_.reset();
    return;
  }
  capacity_ = bytes;
  window_ = w;
  if (cache_)
    cache_->SetCapacity(bytes);
  else
    cache_ = std::make_unique<ShardedPageCache<Window>>(bytes);
}

Status RecordWindows::ReadAlone(uint32_t id, std::vector<uint8_t>* scratch) {
  const BrickEntry& e = table_[id];
  scratch->resize(size_t(e.stored_size) + kTrailerSize);
  Status rs = file_->Read(e.offset, scratch->size(), scratch->data());
  bytes_read_.fetch_add(scratch->size(), std::memory_order_relaxed);
  if (!rs.ok())
    return rs.WithContext("reading brick " + std::to_string(id) + " (offset " +
                          std::to_string(e.offset) + ") in '" + file_->path() + "'");
  return OkStatus();
}

StatusOr<std::shared_ptr<const RecordWindows::Window>> RecordWindows::LoadWindow(uint64_t w,
                                                                                 uint64_t size) {
  // The records starting in [w * size, (w + 1) * size), in file order.
  auto starts_before = [&](uint64_t off) {
    return std::partition_point(order_.begin(), order_.end(),
                                [&](uint32_t id) { return table_[id].offset < off; });
  };
  auto first = starts_before(w * size), last = starts_before((w + 1) * size);
  auto window = std::make_shared<Window>();
  if (first == last) return window;  // unreachable: the asking record starts here
  const BrickEntry& tail = table_[*(last - 1)];
  window->begin = table_[*first].offset;
  window->bytes.resize(tail.offset + tail.stored_size + kTrailerSize - window->begin);
  Status rs = file_->Read(window->begin, window->bytes.size(), window->bytes.data());
  bytes_read_.fetch_add(window->bytes.size(), std::memory_order_relaxed);
  windows_read_.fetch_add(1, std::memory_order_relaxed);
  if (!rs.ok()) return rs;
  return std::shared_ptr<const Window>(std::move(window));
}

void RecordWindows::Forget(uint32_t id) {
  if (window_ != 0) cache_->Erase(WindowKey(table_[id].offset / window_, window_));
}

StatusOr<RecordWindows::Record> RecordWindows::Read(uint32_t id, std::vector<uint8_t>* scratch) {
  const BrickEntry& e = table_[id];
  const uint64_t record = uint64_t(e.stored_size) + kTrailerSize;
  const uint64_t size = window_;
  if (size != 0 && record <= size) {
    const uint64_t w = e.offset / size;
    auto got = cache_->GetOrLoad(
        WindowKey(w, size),
        [&]() -> StatusOr<std::pair<std::shared_ptr<const Window>, size_t>> {
          try {
            VOX_ASSIGN_OR_RETURN(auto win, LoadWindow(w, size));
            const size_t charge = win->bytes.capacity() + sizeof(Window);
            return std::make_pair(std::move(win), charge);
          } catch (const std::bad_alloc&) {
            return ResourceExhaustedError("out of memory reading a window of '" + file_->path() +
                                          "'");
          }
        });
    if (got.ok()) {
      const Window& win = **got;
      if (e.offset >= win.begin && e.offset - win.begin + record <= win.bytes.size())
        return Record{std::move(*got), win.bytes.data() + (e.offset - win.begin)};
    }
    // Otherwise the record alone: its own read reports what went wrong.
  }
  VOX_RETURN_IF_ERROR(ReadAlone(id, scratch));
  return Record{nullptr, scratch->data()};
}

}  // namespace vox::storage_internal

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

RecordWindows::RecordWindows(const RandomAccessFile* file, TablePages* table)
    : file_(file), table_(table) {}

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

Status RecordWindows::ReadAlone(uint32_t id, const BrickEntry& e, std::vector<uint8_t>* scratch) {
  scratch->resize(size_t(e.stored_size) + kTrailerSize);
  Status rs = file_->Read(e.offset, scratch->size(), scratch->data());
  bytes_read_.fetch_add(scratch->size(), std::memory_order_relaxed);
  if (!rs.ok())
    return rs.WithContext("reading brick " + std::to_string(id) + " (offset " +
                          std::to_string(e.offset) + ") in '" + file_->path() + "'");
  return OkStatus();
}

StatusOr<std::shared_ptr<const RecordWindows::Window>> RecordWindows::LoadWindow(
    uint64_t w, uint64_t size, uint32_t id, const BrickEntry& e) {
  // The records starting in [lo, hi) next to brick `id` in the file: from
  // its row outwards, while the ids' records follow each other in the file.
  const uint64_t lo = w * size, hi = (w + 1) * size;
  uint64_t begin = e.offset, end = e.offset + e.stored_size + kTrailerSize;
  for (int dir : {-1, 1}) {
    uint64_t prev = e.offset;
    for (int64_t i = int64_t(id) + dir; i >= 0 && i < int64_t(table_->size());) {
      VOX_ASSIGN_OR_RETURN(TablePages::Rows r, table_->RowsOf(uint32_t(i)));
      bool more = true;
      for (; more && i >= int64_t(r.first) && i < int64_t(r.first + r.rows.size()); i += dir) {
        const BrickEntry& n = r.rows[size_t(i - r.first)];
        more = n.offset >= lo && n.offset < hi && (dir < 0 ? n.offset < prev : n.offset > prev);
        if (!more) break;
        prev = n.offset;
        begin = std::min(begin, n.offset);
        end = std::max(end, n.offset + n.stored_size + kTrailerSize);
      }
      if (!more) break;
    }
  }
  auto window = std::make_shared<Window>();
  window->begin = begin;
  window->bytes.resize(end - begin);
  Status rs = file_->Read(window->begin, window->bytes.size(), window->bytes.data());
  bytes_read_.fetch_add(window->bytes.size(), std::memory_order_relaxed);
  windows_read_.fetch_add(1, std::memory_order_relaxed);
  if (!rs.ok()) return rs;
  return std::shared_ptr<const Window>(std::move(window));
}

void RecordWindows::Forget(const BrickEntry& e) {
  if (window_ != 0) cache_->Erase(WindowKey(e.offset / window_, window_));
}

StatusOr<RecordWindows::Record> RecordWindows::Read(uint32_t id, const BrickEntry& e,
                                                    std::vector<uint8_t>* scratch) {
  const uint64_t record = uint64_t(e.stored_size) + kTrailerSize;
  const uint64_t size = window_;
  if (size != 0 && record <= size) {
    const uint64_t w = e.offset / size;
    auto got = cache_->GetOrLoad(
        WindowKey(w, size),
        [&]() -> StatusOr<std::pair<std::shared_ptr<const Window>, size_t>> {
          try {
            VOX_ASSIGN_OR_RETURN(auto win, LoadWindow(w, size, id, e));
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
  VOX_RETURN_IF_ERROR(ReadAlone(id, e, scratch));
  return Record{nullptr, scratch->data()};
}

}  // namespace vox::storage_internal

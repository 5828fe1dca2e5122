// Store::Prefetch: requested bricks grouped into runs of file neighbours,
// read and decoded ahead on the store's I/O threads (storage/store.h).
#include <algorithm>
#include <mutex>
#include <vector>

#include "storage/internal/store_reader.h"
#include "core/util/memory_budget.h"

namespace vox::storage_internal {

// Queue bound, and how reads of neighbouring bricks merge: a gap up to
// kMaxGap joins the run while the run's gap bytes stay under half its brick
// bytes (plus a page), so a run never reads more than 1.5x what it needs.
// kMaxRun bounds each I/O thread's buffer (the memory budget counts it).
constexpr size_t kMaxPrefetchQueue = size_t(1) << 16;  // bricks
constexpr uint64_t kMaxGap = 4 << 10;  // a page: measured 7% fewer bytes than 32 KiB, same time
constexpr uint64_t kMaxRun = kPrefetchRunBytes;

void StoreImpl::Prefetch(std::span<const uint32_t> brick_ids) {
  if (brick_ids.empty() || table_->size() == 0) return;
  std::vector<uint32_t> ids;
  ids.reserve(brick_ids.size());
  for (uint32_t id : brick_ids)
    if (id < table_->size() && !cache_.Contains(id)) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  // Their rows (a row that cannot be read is left to the brick's own fetch,
  // which reports it), in file order (records lie in the order the ingest
  // wrote them: spatial neighbours close together), so neighbours merge into runs.
  std::vector<std::pair<BrickEntry, uint32_t>> rows;
  rows.reserve(ids.size());
  for (uint32_t id : ids) {
    auto e = table_->Entry(id);
    if (e.ok()) rows.emplace_back(*e, id);
  }
  std::sort(rows.begin(), rows.end(),
            [](const auto& a, const auto& b) { return a.first.offset < b.first.offset; });
  std::vector<Run> runs;
  for (size_t i = 0; i < rows.size();) {
    const uint64_t begin = rows[i].first.offset;
    uint64_t end = begin + rows[i].first.stored_size + kTrailerSize;
    uint64_t useful = end - begin, gaps = 0;
    Run run;
    run.ids.push_back(rows[i].second);
    run.rows.push_back(rows[i].first);
    run.raw = DecodedCharge(rows[i].first);
    size_t j = i + 1;
    for (; j < rows.size(); ++j) {
      const BrickEntry& e = rows[j].first;
      const uint64_t size = e.stored_size + kTrailerSize;
      const uint64_t gap = e.offset >= end ? e.offset - end : 0;
      if (e.offset < end || gap > kMaxGap || 2 * (gaps + gap) > useful + size + 8192 ||
          e.offset + size - begin > kMaxRun)
        break;
      gaps += gap;
      useful += size;
      end = e.offset + size;
      run.ids.push_back(rows[j].second);
      run.rows.push_back(e);
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
  std::vector<const BrickEntry*> rows;  // claimed bricks' rows
  claimed.reserve(run.ids.size());
  for (size_t k = 0; k < run.ids.size(); ++k)
    if (cache_.Claim(run.ids[k])) {
      claimed.push_back(run.ids[k]);
      rows.push_back(&run.rows[k]);
    }
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
  const uint64_t begin = rows.front()->offset;
  const uint64_t end = rows.back()->offset + rows.back()->stored_size + kTrailerSize;
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
      auto b = DecodeRecord(id, *rows[next], buf->data() + (rows[next]->offset - begin));
      if (!b.ok()) {
        pf_failed_.fetch_add(1, std::memory_order_relaxed);
        cache_.FinishClaim(id, nullptr, 0);
        continue;
      }
      const size_t charge = (*b)->charge();
      cache_.FinishClaim(id, std::shared_ptr<const DecodedBrick>(std::move(*b)), charge);
      AbsorbHeapGrowth(charge);
    }
  } catch (const std::exception&) {  // out of memory: the fetches try again
    pf_failed_.fetch_add(claimed.size() - next, std::memory_order_relaxed);
    release_rest();
  }
}

}  // namespace vox::storage_internal

// Fuzz target: a store's two files (index.vxi, bricks.vxb) opened from
// memory, every brick fetched and a few rays traced. Input layout (see
// fuzz_input.h): a mode byte, the index length, the index, the bricks.
// Mode bit 0 recomputes every checksum first (file headers, footer, index
// blocks, brick records and their table rows), so mutations reach the
// decoders behind the CRCs. Any input must give a Status, never a crash.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/tracer.h"
#include "core/util/file.h"
#include "storage/internal/store_impl.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vox;
  fuzz::StoreInput in = fuzz::SplitStoreInput(data, size);
  if (in.mode & fuzz::kFixChecksums) fuzz::FixChecksums(&in.index, &in.bricks);
  OpenOptions oo;
  oo.cache_bytes = size_t(1) << 20;  // the memory budget a fuzzed brick must fit
  oo.verify_checksums = (in.mode & fuzz::kSkipBrickChecksums) == 0;
  auto store = storage_internal::OpenStoreFromFiles(
      "fuzz", NewMemoryFile("fuzz/index.vxi", std::move(in.index)),
      NewMemoryFile("fuzz/bricks.vxb", std::move(in.bricks)), oo);
  if (!store.ok()) return 0;
  Store& s = **store;
  const uint64_t bricks = s.meta().brick_count;
  for (uint32_t id = 0; id < bricks && id < 4096; ++id) {
    auto b = s.FetchBrick(id);
    if (!b.ok()) continue;
    if (b->num_cells > 0 && b->cells == nullptr) __builtin_trap();
  }
  auto tracer = vox::AutoTracer<>::Create(s.view(), s.meta().brick_level);
  if (!tracer.ok()) return 0;
  const double n = double(uint64_t(1) << std::min(s.meta().levels, 40));
  for (int i = 0; i < 8; ++i) {
    vox::Ray r{{-1.0, n * (0.1 + 0.1 * i), n * 0.45}, {1.0, 0.01 * i, 0.02}};
    (void)tracer->Traverse(r, [&](const vox::Hit& h) { return s.Attributes(h.brick, h.payload).ok(); });
  }
  return 0;
}

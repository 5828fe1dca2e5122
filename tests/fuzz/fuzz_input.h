// Input layouts shared by the fuzz targets, their seed generator and the
// corpus replay test. Header only; stateless; thread-safe.
//
// Store input: byte 0 is a mode (kFixChecksums, kSkipBrickChecksums),
// bytes 1..4 the index file's length L (little-endian, clamped to what is
// there), then L bytes of index.vxi, then the rest as bricks.vxb.
#ifndef VOX_TESTS_FUZZ_FUZZ_INPUT_H_
#define VOX_TESTS_FUZZ_FUZZ_INPUT_H_

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include "core/util/crc32c.h"
#include "storage/internal/coding.h"
#include "storage/internal/format.h"

namespace vox::fuzz {

inline constexpr uint8_t kFixChecksums = 1, kSkipBrickChecksums = 2;

struct StoreInput {
  uint8_t mode = 0;
  std::string index, bricks;
};

inline StoreInput SplitStoreInput(const uint8_t* data, size_t size) {
  StoreInput in;
  if (size < 5) return in;
  in.mode = data[0];
  uint32_t len = uint32_t(data[1]) | uint32_t(data[2]) << 8 | uint32_t(data[3]) << 16 |
                 uint32_t(data[4]) << 24;
  len = uint32_t(std::min<size_t>(len, size - 5));
  in.index.assign(reinterpret_cast<const char*>(data + 5), len);
  in.bricks.assign(reinterpret_cast<const char*>(data + 5 + len), size - 5 - len);
  return in;
}

inline std::string JoinStoreInput(uint8_t mode, const std::string& index, const std::string& bricks) {
  std::string s(1, char(mode));
  const uint32_t len = uint32_t(index.size());
  for (int i = 0; i < 4; ++i) s += char((len >> (8 * i)) & 0xff);
  return s + index + bricks;
}

// Recomputes every checksum the store format has, wherever the structure is
// still readable: both file headers, the footer, the index blocks' trailers,
// each brick record's trailer and its table row's copy of it.
inline void FixChecksums(std::string* index, std::string* bricks) {
  using namespace storage_internal;
  auto fix_header = [](std::string* f) {
    if (f->size() < kFileHeaderSize) return;
    uint8_t* p = reinterpret_cast<uint8_t*>(f->data());
    EncodeFixed32(p + 28, crc32c::Mask(crc32c::Value(p, 28)));
  };
  fix_header(index);
  fix_header(bricks);
  if (index->size() < kFileHeaderSize + kFooterSize) return;
  uint8_t* ix = reinterpret_cast<uint8_t*>(index->data());
  const size_t isize = index->size();
  uint8_t* foot = ix + isize - kFooterSize;
  EncodeFixed32(foot + 92, crc32c::Mask(crc32c::Value(foot, 92)));
  const uint64_t blocks_end = isize - kFooterSize;
  BlockHandle table{0, 0};
  for (int i = 0; i < 4; ++i) {
    const uint64_t off = DecodeFixed64(foot + 16 * i), n = DecodeFixed64(foot + 16 * i + 8);
    if (off > blocks_end || n > blocks_end - off || kTrailerSize > blocks_end - off - n) continue;
    if (i == 3) table = {off, n};
    uint8_t* t = ix + off + n;
    const uint8_t codec = t[0];
    const std::string tr = BlockTrailer(ix + off, n, codec);
    std::memcpy(t, tr.data(), tr.size());
  }
  // Brick records and their table rows.
  uint8_t* bx = reinterpret_cast<uint8_t*>(bricks->data());
  const uint64_t bsize = bricks->size();
  for (uint64_t r = 0; r + kTableEntrySize <= table.size; r += kTableEntrySize) {
    uint8_t* row = ix + table.offset + r;
    const uint64_t off = DecodeFixed64(row);
    const uint64_t n = DecodeFixed32(row + 32);
    if (off > bsize || n + kTrailerSize > bsize - off) continue;
    const uint8_t codec = bx[off + n];
    const std::string tr = BlockTrailer(bx + off, n, codec);
    std::memcpy(bx + off + n, tr.data(), tr.size());
    std::memcpy(row + 48, tr.data() + 1, 4);
  }
  if (table.size > 0) {  // the table block changed: its trailer again
    const std::string tr = BlockTrailer(ix + table.offset, table.size, ix[table.offset + table.size]);
    std::memcpy(ix + table.offset + table.size, tr.data(), tr.size());
  }
}

}  // namespace vox::fuzz

#endif  // VOX_TESTS_FUZZ_FUZZ_INPUT_H_

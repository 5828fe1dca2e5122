#include "core/util/crc32c.h"

#include <array>
#include <cstring>

#if defined(__x86_64__)
#include <nmmintrin.h>
#endif

namespace vox::crc32c {
namespace {

// Slicing-by-4 tables: kTable[0] is the byte-at-a-time table; kTable[k][b]
// is the CRC of byte b followed by k zero bytes.
constexpr std::array<std::array<uint32_t, 256>, 4> MakeTables() {
  std::array<std::array<uint32_t, 256>, 4> t{};
  for (uint32_t b = 0; b < 256; ++b) {
    uint32_t c = b;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
    t[0][b] = c;
  }
  for (uint32_t b = 0; b < 256; ++b)
    for (int k = 1; k < 4; ++k) t[k][b] = (t[k - 1][b] >> 8) ^ t[0][t[k - 1][b] & 0xff];
  return t;
}
constexpr auto kTable = MakeTables();

#if defined(__x86_64__)
// Eight bytes per crc32 instruction (about 10x the tables on a brick).
__attribute__((target("sse4.2"))) uint32_t ExtendSse42(uint32_t crc, const uint8_t* p, size_t n) {
  uint64_t c = ~crc;
  for (; n > 0 && (reinterpret_cast<uintptr_t>(p) & 7) != 0; --n) c = _mm_crc32_u8(uint32_t(c), *p++);
  for (; n >= 8; n -= 8, p += 8) {
    uint64_t w;
    std::memcpy(&w, p, 8);
    c = _mm_crc32_u64(c, w);
  }
  for (; n > 0; --n) c = _mm_crc32_u8(uint32_t(c), *p++);
  return ~uint32_t(c);
}
#endif

}  // namespace

uint32_t Extend(uint32_t crc, const void* data, size_t n) {
#if defined(__x86_64__)
  static const bool sse42 = __builtin_cpu_supports("sse4.2");
  if (sse42) return ExtendSse42(crc, static_cast<const uint8_t*>(data), n);
#endif
  return ExtendPortable(crc, data, n);
}

uint32_t ExtendPortable(uint32_t crc, const void* data, size_t n) {
  const uint8_t* p = static_cast<const uint8_t*>(data);
  uint32_t c = ~crc;
  // Byte at a time until 4-byte aligned, then 4 bytes per step.
  while (n > 0 && (reinterpret_cast<uintptr_t>(p) & 3) != 0) {
    c = kTable[0][(c ^ *p++) & 0xff] ^ (c >> 8);
    --n;
  }
  while (n >= 4) {
    uint32_t w;
    std::memcpy(&w, p, 4);  // little-endian host (see internal/coding.h)
    c ^= w;
    c = kTable[3][c & 0xff] ^ kTable[2][(c >> 8) & 0xff] ^ kTable[1][(c >> 16) & 0xff] ^
        kTable[0][c >> 24];
    p += 4;
    n -= 4;
  }
  while (n > 0) {
    c = kTable[0][(c ^ *p++) & 0xff] ^ (c >> 8);
    --n;
  }
  return ~c;
}

}  // namespace vox::crc32c

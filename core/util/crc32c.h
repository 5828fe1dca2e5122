// CRC32C (Castagnoli polynomial 0x1EDC6F41, reflected 0x82F63B78): the
// SSE4.2 crc32 instruction where the CPU has it (chosen once, at run time),
// tables otherwise; plus LevelDB's mask for CRCs stored next to the data
// they cover.
// Stateless functions; thread-safe.
#ifndef VOX_CORE_UTIL_CRC32C_H_
#define VOX_CORE_UTIL_CRC32C_H_

#include <cstddef>
#include <cstdint>

namespace vox::crc32c {

// The CRC32C of data[0, n) appended to the bytes whose CRC is `crc`.
uint32_t Extend(uint32_t crc, const void* data, size_t n);
// Extend by tables only, whatever the CPU (for tests of the fast path).
uint32_t ExtendPortable(uint32_t crc, const void* data, size_t n);
// The CRC32C of data[0, n). Value("123456789") == 0xE3069283.
inline uint32_t Value(const void* data, size_t n) { return Extend(0, data, n); }

// Stored CRCs are masked, so that the CRC of a string containing embedded
// CRCs stays well distributed (LevelDB's util/crc32c.h).
inline constexpr uint32_t kMaskDelta = 0xa282ead8u;
inline uint32_t Mask(uint32_t crc) { return ((crc >> 15) | (crc << 17)) + kMaskDelta; }
inline uint32_t Unmask(uint32_t masked) {
  uint32_t rot = masked - kMaskDelta;
  return (rot >> 17) | (rot << 15);
}

}  // namespace vox::crc32c

#endif  // VOX_CORE_UTIL_CRC32C_H_

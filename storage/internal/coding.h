// Little-endian fixed-width encoding helpers for vox's on-disk structs
// (storage/FORMAT.md), in the spirit of LevelDB's util/coding.h. Stateless
// functions; thread-safe.
#ifndef VOX_STORAGE_INTERNAL_CODING_H_
#define VOX_STORAGE_INTERNAL_CODING_H_

#include <bit>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace vox::storage_internal {

static_assert(std::endian::native == std::endian::little,
              "vox stores cells as raw little-endian uint32; a big-endian port must byte-swap");

inline void EncodeFixed16(uint8_t* p, uint16_t v) { std::memcpy(p, &v, 2); }
inline void EncodeFixed32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }
inline void EncodeFixed64(uint8_t* p, uint64_t v) { std::memcpy(p, &v, 8); }
inline uint16_t DecodeFixed16(const uint8_t* p) { uint16_t v; std::memcpy(&v, p, 2); return v; }
inline uint32_t DecodeFixed32(const uint8_t* p) { uint32_t v; std::memcpy(&v, p, 4); return v; }
inline uint64_t DecodeFixed64(const uint8_t* p) { uint64_t v; std::memcpy(&v, p, 8); return v; }

inline void PutFixed32(std::string* dst, uint32_t v) {
  uint8_t b[4];
  EncodeFixed32(b, v);
  dst->append(reinterpret_cast<const char*>(b), 4);
}
inline void PutFixed64(std::string* dst, uint64_t v) {
  uint8_t b[8];
  EncodeFixed64(b, v);
  dst->append(reinterpret_cast<const char*>(b), 8);
}
inline void PutDouble(std::string* dst, double d) { PutFixed64(dst, std::bit_cast<uint64_t>(d)); }
// A length-prefixed string: fixed32 length, then the bytes.
inline void PutString(std::string* dst, std::string_view s) {
  PutFixed32(dst, uint32_t(s.size()));
  dst->append(s);
}

// Reads fields from a block, failing (not crashing) when it runs out.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : p_(data), end_(data + size) {}
  bool ok() const { return ok_; }
  size_t remaining() const { return size_t(end_ - p_); }
  uint8_t U8() { return Need(1) ? *p_++ : 0; }
  uint32_t U32() {
    if (!Need(4)) return 0;
    uint32_t v = DecodeFixed32(p_);
    p_ += 4;
    return v;
  }
  uint64_t U64() {
    if (!Need(8)) return 0;
    uint64_t v = DecodeFixed64(p_);
    p_ += 8;
    return v;
  }
  int64_t I64() { return int64_t(U64()); }
  double F64() { return std::bit_cast<double>(U64()); }
  std::string String() {
    uint32_t n = U32();
    if (!Need(n)) return {};
    std::string s(reinterpret_cast<const char*>(p_), n);
    p_ += n;
    return s;
  }

 private:
  bool Need(size_t n) {
    if (!ok_ || remaining() < n) {
      ok_ = false;
      return false;
    }
    return true;
  }
  const uint8_t* p_;
  const uint8_t* end_;
  bool ok_ = true;
};

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_CODING_H_

// An array's elements as floats: numpy's dtype names, the element loaders
// and the shape check, shared by the array's two ingests (array_ingest.cpp:
// the array as a .vdb file; array_stream.cpp: the array straight into a
// store). Private to ingest and its tests.
//
// Thread safety: stateless; thread-safe.
#ifndef VOX_INGEST_INTERNAL_ARRAY_VALUES_H_
#define VOX_INGEST_INTERNAL_ARRAY_VALUES_H_

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/util/status.h"
#include "ingest/array_ingest.h"

namespace vox::ingest_internal {

// numpy's names and descr strings -> a canonical "f4", "u1", "i2", ...
inline StatusOr<std::string> CanonicalDtype(const std::string& dtype) {
  static const std::pair<const char*, const char*> kNames[] = {
      {"float32", "f4"}, {"float64", "f8"}, {"uint8", "u1"}, {"uint16", "u2"},
      {"uint32", "u4"},  {"uint64", "u8"},  {"int8", "i1"},  {"int16", "i2"},
      {"int32", "i4"},   {"int64", "i8"},   {"float", "f4"}, {"double", "f8"}};
  for (auto& [name, code] : kNames)
    if (dtype == name) return std::string(code);
  std::string d = dtype;
  if (!d.empty() && (d[0] == '<' || d[0] == '|' || d[0] == '=')) d = d.substr(1);
  static const char* kCodes[] = {"f4", "f8", "u1", "u2", "u4", "u8", "i1", "i2", "i4", "i8"};
  for (const char* c : kCodes)
    if (d == c) return d;
  return InvalidArgumentError("dtype '" + dtype +
                              "' is not supported: give float32, float64, (u)int8, (u)int16, "
                              "(u)int32 or (u)int64, little-endian");
}

template <class T>
float LoadElement(const void* base, size_t index) {
  T v;
  std::memcpy(&v, static_cast<const char*>(base) + index * sizeof(T), sizeof(T));
  return float(v);
}

// Element `index` of the array's memory as a float (the density a store keeps).
using ElementLoader = float (*)(const void*, size_t);

inline ElementLoader LoaderOf(const std::string& code) {
  if (code == "f4") return LoadElement<float>;
  if (code == "f8") return LoadElement<double>;
  if (code == "u1") return LoadElement<uint8_t>;
  if (code == "u2") return LoadElement<uint16_t>;
  if (code == "u4") return LoadElement<uint32_t>;
  if (code == "u8") return LoadElement<uint64_t>;
  if (code == "i1") return LoadElement<int8_t>;
  if (code == "i2") return LoadElement<int16_t>;
  if (code == "i4") return LoadElement<int32_t>;
  return LoadElement<int64_t>;
}

inline Status CheckArrayShape(const std::array<int64_t, 3>& s, const std::string& what) {
  for (int a = 0; a < 3; ++a)
    if (s[size_t(a)] <= 0 || s[size_t(a)] > (int64_t(1) << 31))
      return InvalidArgumentError(what + ": shape " + std::to_string(s[0]) + " x " +
                                  std::to_string(s[1]) + " x " + std::to_string(s[2]) +
                                  " is not 3 positive sizes below 2^31");
  return OkStatus();
}

// The placement's own checks (the voxel size, the threshold, the index range).
inline Status CheckArrayPlacement(const ArrayView& a, const ArrayPlacement& place,
                                  const std::string& what) {
  if (!(place.voxel_size > 0) || !std::isfinite(place.voxel_size))
    return InvalidArgumentError(what + ": voxel_size must be positive");
  if (!std::isfinite(place.threshold))
    return InvalidArgumentError(what + ": threshold must be finite");
  constexpr int64_t kRange = int64_t(1) << 30;
  for (int c = 0; c < 3; ++c) {
    const int64_t o = place.origin[size_t(c)];  // (checked before llabs: not INT64_MIN)
    if (o < -kRange || o > kRange || std::llabs(o) + a.shape[size_t(c)] > kRange)
      return InvalidArgumentError(what + ": origin + shape leaves OpenVDB's index range");
  }
  return OkStatus();
}

// The memory index of element [i, j, k].
inline size_t ElementIndex(const ArrayView& a, int64_t i, int64_t j, int64_t k) {
  const int64_t nx = a.shape[0], ny = a.shape[1], nz = a.shape[2];
  return a.fortran_order ? size_t((k * ny + j) * nx + i) : size_t((i * ny + j) * nz + k);
}

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_ARRAY_VALUES_H_

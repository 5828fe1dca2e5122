#include "storage/internal/brick_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <glm/gtc/packing.hpp>

#include "storage/internal/brick_uniform.h"
#include "storage/internal/coding.h"

namespace vox::storage_internal {

uint64_t MaxCells(int depth, uint64_t voxels) {
  if (depth < 1 || depth > kMaxLevels) return 0;
  if (depth < 21 && voxels > (uint64_t(1) << (3 * depth))) return 0;
  uint64_t total = 0, level = 1;
  for (int l = 0; l < depth; ++l) {
    total += std::min(level, voxels);
    if (level < voxels) level *= 8;
  }
  return total;
}

uint32_t EncodeOctNormal(const glm::vec3& n, int bits) {
  float s = std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z);
  float px = 0, py = 0;
  if (std::isfinite(s) && s > 0) {
    px = n.x / s;
    py = n.y / s;
    if (n.z < 0) {
      float ox = (1 - std::fabs(py)) * (px >= 0 ? 1.f : -1.f);
      float oy = (1 - std::fabs(px)) * (py >= 0 ? 1.f : -1.f);
      px = ox;
      py = oy;
    }
  }
  const uint32_t step = uint32_t(1) << (16 - std::clamp(bits, 8, 16));
  const uint32_t top = 65535 / step * step;
  const double per_step = 1.0 / step;  // a power of two: the product is the quotient, exactly
  auto q = [&](float v) {
    double t = std::clamp(double(v) * 0.5 + 0.5, 0.0, 1.0) * 65535.0 * per_step;
    // std::lround(t) for t >= 0, without the library call: t's fraction
    // (exact) rounds half up.
    uint32_t r = uint32_t(t);
    if (t - double(r) >= 0.5) ++r;
    return std::min(r * step, top);
  };
  return q(px) | (q(py) << 16);
}

glm::vec3 DecodeOctNormal(uint32_t code) {
  float px = float(code & 0xffff) / 65535.f * 2 - 1;
  float py = float(code >> 16) / 65535.f * 2 - 1;
  glm::vec3 n(px, py, 1 - std::fabs(px) - std::fabs(py));
  if (n.z < 0) {
    float ox = (1 - std::fabs(py)) * (px >= 0 ? 1.f : -1.f);
    float oy = (1 - std::fabs(px)) * (py >= 0 ? 1.f : -1.f);
    n.x = ox;
    n.y = oy;
  }
  float len = std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
  return n / len;
}

// Planar layout: for each attribute in flag order, each byte of its encoded
// value is one plane of `count` bytes (byte 0 of every voxel, then byte 1 ...).
// Shuffled bytes compress far better than interleaved ones.
namespace {
inline void ScatterPlanes(uint8_t* planes, uint32_t count, uint32_t index, int nbytes,
                          uint64_t v) {
  for (int b = 0; b < nbytes; ++b) planes[size_t(b) * count + index] = uint8_t(v >> (8 * b));
}

// Attribute components (width in bytes) in plane order, for delta coding:
// at most kMaxComponents (normal 2, density 1, colour 3, coverage 1, temperature 1).
constexpr int kMaxComponents = 8;
int Components(uint8_t flags, int* widths) {
  int k = 0;
  if (flags & kAttrNormal) widths[k++] = 2, widths[k++] = 2;
  if (flags & kAttrDensity) widths[k++] = 4;
  if (flags & kAttrColor) widths[k++] = 2, widths[k++] = 2, widths[k++] = 2;
  if (flags & kAttrCoverage) widths[k++] = 2;
  if (flags & kAttrTemperature) widths[k++] = 4;
  return k;
}

// Replaces each component's values by their differences (mod 2^(8 width))
// from the previous voxel's. Neighbours in Morton order have similar
// normals, densities and colours: small differences compress well.
template <int W>
void DeltaComponent(uint8_t* planes, uint32_t count) {
  using T = std::conditional_t<W == 2, uint16_t, uint32_t>;
  uint8_t* p[W];
  for (int b = 0; b < W; ++b) p[b] = planes + size_t(b) * count;
  T prev = 0;
  for (uint32_t i = 0; i < count; ++i) {
    T v = 0;
    for (int b = 0; b < W; ++b) v = T(v | (T(p[b][i]) << (8 * b)));
    const T out = T(v - prev);
    for (int b = 0; b < W; ++b) p[b][i] = uint8_t(out >> (8 * b));
    prev = v;
  }
}

// Undoes DeltaComponent, reading the differences from `src`'s planes and
// writing the values to `dst` as one array of `count` W-byte little-endian
// values, so a decoder regroups its planes out of the decompressed record
// in the same pass.
template <int W>
void UndeltaComponent(const uint8_t* src, uint8_t* dst, uint32_t count) {
  using T = std::conditional_t<W == 2, uint16_t, uint32_t>;
  const uint8_t* p[W];
  for (int b = 0; b < W; ++b) p[b] = src + size_t(b) * count;
  T prev = 0;
  // Decoding runs on every brick a reader loads. With SSE2 (x86-64's
  // baseline) the byte planes are joined into lanes, each lane gets its
  // predecessors' sum in shifted adds plus the running total, and the lanes
  // are stored as they are: 8 two-byte values or 16 four-byte ones a step.
  uint32_t i = 0;
#if defined(__SSE2__)
  if constexpr (W == 2) {
    __m128i carry = _mm_set1_epi16(0);
    for (; i + 8 <= count; i += 8) {
      const __m128i lo = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(p[0] + i));
      const __m128i hi = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(p[1] + i));
      __m128i v = _mm_unpacklo_epi8(lo, hi);  // 8 x uint16
      v = _mm_add_epi16(v, _mm_slli_si128(v, 2));
      v = _mm_add_epi16(v, _mm_slli_si128(v, 4));
      v = _mm_add_epi16(v, _mm_slli_si128(v, 8));
      v = _mm_add_epi16(v, carry);
      carry = _mm_shuffle_epi32(_mm_shufflehi_epi16(v, 0xff), 0xff);  // lane 7 everywhere
      _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + size_t(2) * i), v);
    }
    prev = T(_mm_extract_epi16(carry, 0));
  }
  if constexpr (W == 4) {
    __m128i carry = _mm_setzero_si128();
    for (; i + 16 <= count; i += 16) {
      __m128i b[4];
      for (int k = 0; k < 4; ++k) b[k] = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p[k] + i));
      const __m128i lo01 = _mm_unpacklo_epi8(b[0], b[1]), hi01 = _mm_unpackhi_epi8(b[0], b[1]);
      const __m128i lo23 = _mm_unpacklo_epi8(b[2], b[3]), hi23 = _mm_unpackhi_epi8(b[2], b[3]);
      const __m128i v[4] = {_mm_unpacklo_epi16(lo01, lo23), _mm_unpackhi_epi16(lo01, lo23),
                            _mm_unpacklo_epi16(hi01, hi23), _mm_unpackhi_epi16(hi01, hi23)};
      for (int k = 0; k < 4; ++k) {  // voxels i + 4k .. i + 4k + 3
        __m128i x = v[k];
        x = _mm_add_epi32(x, _mm_slli_si128(x, 4));
        x = _mm_add_epi32(x, _mm_slli_si128(x, 8));
        x = _mm_add_epi32(x, carry);
        carry = _mm_shuffle_epi32(x, 0xff);  // lane 3 everywhere
        _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + size_t(4) * (i + 4 * k)), x);
      }
    }
    prev = T(_mm_cvtsi128_si32(carry));
  }
#endif
  for (; i < count; ++i) {
    T d = 0;
    for (int b = 0; b < W; ++b) d = T(d | (T(p[b][i]) << (8 * b)));
    prev = T(prev + d);
    for (int b = 0; b < W; ++b) dst[size_t(W) * i + b] = uint8_t(prev >> (8 * b));
  }
}

void DeltaPlanes(uint8_t* planes, uint32_t count, uint8_t flags) {
  int widths[kMaxComponents];
  int n = Components(flags, widths);
  for (int c = 0; c < n; ++c) {
    if (widths[c] == 2) DeltaComponent<2>(planes, count);
    else DeltaComponent<4>(planes, count);
    planes += size_t(widths[c]) * count;
  }
}

// DeltaPlanes undone from `src`'s planes into `dst`'s value arrays (all
// AttrBytesPerVoxel(flags) * count bytes of it are written).
void UndeltaPlanes(const uint8_t* src, uint8_t* dst, uint32_t count, uint8_t flags) {
  int widths[kMaxComponents];
  int n = Components(flags, widths);
  for (int c = 0; c < n; ++c) {
    if (widths[c] == 2) UndeltaComponent<2>(src, dst, count);
    else UndeltaComponent<4>(src, dst, count);
    src += size_t(widths[c]) * count;
    dst += size_t(widths[c]) * count;
  }
}
}  // namespace

namespace {
// Component value `index` of the array at `values` (little-endian, W bytes).
template <int W>
uint32_t ValueAt(const uint8_t* values, uint32_t index) {
  const uint8_t* p = values + size_t(W) * index;
  uint32_t v = 0;
  for (int b = 0; b < W; ++b) v |= uint32_t(p[b]) << (8 * b);
  return v;
}
}  // namespace

VoxelAttributes ReadAttributes(const uint8_t* values, uint32_t count, uint8_t flags,
                               uint32_t index) {
  VoxelAttributes a;
  if (flags & kAttrNormal) {
    a.normal = DecodeOctNormal(ValueAt<2>(values, index) |
                               ValueAt<2>(values + size_t(2) * count, index) << 16);
    values += size_t(4) * count;
  }
  if (flags & kAttrDensity) {
    a.density = std::bit_cast<float>(ValueAt<4>(values, index));
    values += size_t(4) * count;
  }
  if (flags & kAttrColor) {
    for (int k = 0; k < 3; ++k)
      a.color[k] = glm::unpackHalf1x16(uint16_t(ValueAt<2>(values + size_t(2 * k) * count, index)));
    values += size_t(6) * count;
  }
  if (flags & kAttrCoverage) {
    a.coverage = DecodeCoverage(uint16_t(ValueAt<2>(values, index)));
    values += size_t(2) * count;
  }
  if (flags & kAttrTemperature) a.temperature = std::bit_cast<float>(ValueAt<4>(values, index));
  return a;
}

std::vector<uint8_t> PlanesToValues(std::span<const uint8_t> planes, uint32_t count, uint8_t flags) {
  std::vector<uint8_t> out(planes.size());
  int widths[kMaxComponents];
  const int n = Components(flags, widths);
  size_t at = 0;
  for (int c = 0; c < n && at + size_t(widths[c]) * count <= planes.size(); ++c) {
    const int w = widths[c];
    for (uint32_t i = 0; i < count; ++i)
      for (int b = 0; b < w; ++b) out[at + size_t(w) * i + b] = planes[at + size_t(b) * count + i];
    at += size_t(w) * count;
  }
  return out;
}

void WriteAttributes(std::span<const VoxelAttributes> attrs, uint8_t flags, std::string* dst,
                     int normal_bits) {
  const uint32_t count = uint32_t(attrs.size());
  size_t start = dst->size();
  dst->resize(start + AttrBytesPerVoxel(flags) * count);
  uint8_t* planes = reinterpret_cast<uint8_t*>(dst->data()) + start;
  if (flags & kAttrNormal) {
    for (uint32_t i = 0; i < count; ++i)
      ScatterPlanes(planes, count, i, 4, EncodeOctNormal(attrs[i].normal, normal_bits));
    planes += size_t(4) * count;
  }
  if (flags & kAttrDensity) {
    for (uint32_t i = 0; i < count; ++i)
      ScatterPlanes(planes, count, i, 4, std::bit_cast<uint32_t>(attrs[i].density));
    planes += size_t(4) * count;
  }
  if (flags & kAttrColor) {
    for (uint32_t i = 0; i < count; ++i) {
      uint64_t c = 0;
      for (int k = 0; k < 3; ++k) c |= uint64_t(glm::packHalf1x16(attrs[i].color[k])) << (16 * k);
      ScatterPlanes(planes, count, i, 6, c);
    }
    planes += size_t(6) * count;
  }
  if (flags & kAttrCoverage) {
    for (uint32_t i = 0; i < count; ++i)
      ScatterPlanes(planes, count, i, 2, EncodeCoverage(attrs[i].coverage));
    planes += size_t(2) * count;
  }
  if (flags & kAttrTemperature)
    for (uint32_t i = 0; i < count; ++i)
      ScatterPlanes(planes, count, i, 4, std::bit_cast<uint32_t>(attrs[i].temperature));
}

std::string EncodeBrickRaw(std::span<const Cell> cells, std::span<const VoxelAttributes> attrs,
                           int depth, uint8_t flags, int normal_bits) {
  std::string s;
  s.reserve(kBrickHeaderSize + cells.size() + attrs.size() * AttrBytesPerVoxel(flags));
  PutFixed32(&s, uint32_t(cells.size()));
  PutFixed32(&s, uint32_t(attrs.size()));
  s.push_back(char(depth));
  s.push_back(char(flags));
  s.append(6, '\0');
  for (const Cell& c : cells) {
    uint8_t mask = 0;
    for (int d = 0; d < 8; ++d)
      if (c.child[d] != kEmptyRef) mask |= uint8_t(1u << d);
    s.push_back(char(mask));
  }
  size_t at = s.size();
  WriteAttributes(attrs, flags, &s, normal_bits);
  DeltaPlanes(reinterpret_cast<uint8_t*>(s.data()) + at, uint32_t(attrs.size()), flags);
  return s;
}

namespace {

// Checks pre-order child masks and finds each cell's level: the structure
// BuildCells would give (every cell has a child, leaves exactly at the last
// level, as many cells and leaves as the header says). Refuses anything else.
struct MaskChecker {
  const uint8_t* masks;
  uint32_t num_cells, voxel_count;
  uint8_t* level;  // per cell, 0 for the root
  uint32_t next_cell = 1, next_payload = 0;
  const char* error = nullptr;

  bool Check(uint32_t index, int l, int levels) {
    const uint8_t m = masks[index];
    level[index] = uint8_t(l);
    if (m == 0) {
      error = "a cell with no children";
      return false;
    }
    if (l == levels - 1) {
      if (uint64_t(next_payload) + uint64_t(Popcount8(m)) > voxel_count) {
        error = "more voxels than its table row says";
        return false;
      }
      next_payload += Popcount8(m);
      return true;
    }
    for (int k = int(Popcount8(m)); k > 0; --k) {
      if (next_cell >= num_cells) {
        error = "more cells than its table row says";
        return false;
      }
      if (!Check(next_cell++, l + 1, levels)) return false;
    }
    return true;
  }
};

}  // namespace

StatusOr<std::shared_ptr<DecodedBrick>> DecodeBrickRaw(const uint8_t* raw, size_t n,
                                                       const BrickEntry& entry, int depth,
                                                       uint8_t flags) {
  if (n < kBrickHeaderSize) return CorruptionError("brick shorter than its header");
  uint32_t num_cells = DecodeFixed32(raw), voxel_count = DecodeFixed32(raw + 4);
  int d = raw[8];
  uint8_t f = raw[9];
  if (num_cells != entry.num_cells || voxel_count != entry.voxel_count)
    return CorruptionError("brick header says " + std::to_string(num_cells) + " cells, " +
                           std::to_string(voxel_count) + " voxels; its table row says " +
                           std::to_string(entry.num_cells) + ", " +
                           std::to_string(entry.voxel_count));
  if (d != depth) return CorruptionError("brick has depth " + std::to_string(d) +
                                         ", the store's bricks have " + std::to_string(depth));
  if (f != flags) return CorruptionError("brick attribute flags " + std::to_string(f) +
                                         " differ from the store's " + std::to_string(flags));
  uint64_t expect = kBrickHeaderSize + uint64_t(num_cells) +
                    uint64_t(voxel_count) * AttrBytesPerVoxel(flags);
  if (expect != n)
    return CorruptionError("brick is " + std::to_string(n) + " bytes; its header implies " +
                           std::to_string(expect));
  if (num_cells == 0 || voxel_count == 0 || num_cells > MaxCells(depth, voxel_count))
    return CorruptionError("brick has " + std::to_string(num_cells) + " cells for " +
                           std::to_string(voxel_count) + " voxels");
  if (num_cells > kMaxCompactIndex + 1 || voxel_count > kMaxCompactIndex + 1)
    return CorruptionError("brick has " + std::to_string(num_cells) + " cells, " +
                           std::to_string(voxel_count) +
                           " voxels: more than the 2^24 a traversal pool indexes");
  if (depth < 1 || depth > kMaxLevels)
    return CorruptionError("brick depth " + std::to_string(depth) + " out of range");
  const uint8_t* masks = raw + kBrickHeaderSize;
  // (a full pre-order pool of all masks 0xff is valid by construction)
  if (auto full = DecodeFullOfOne(masks, num_cells, masks + num_cells, voxel_count, depth, flags))
    return full;
  thread_local std::vector<uint8_t> level;
  level.resize(num_cells);
  MaskChecker check{masks, num_cells, voxel_count, level.data(), 1, 0, nullptr};
  if (!check.Check(0, 0, depth))
    return CorruptionError(std::string("brick topology has ") + check.error);
  if (check.next_cell != num_cells || check.next_payload != voxel_count)
    return CorruptionError("brick topology reaches " + std::to_string(check.next_cell) +
                           " cells, " + std::to_string(check.next_payload) +
                           " voxels; header says " + std::to_string(num_cells) + ", " +
                           std::to_string(voxel_count));
  // Level order from pre-order: a level's cells keep their pre-order order,
  // and a cell's first child is the next cell in pre-order, so one pass in
  // pre-order numbers each cell and knows its first child's number.
  uint32_t start[kMaxLevels + 1] = {}, count[kMaxLevels + 1] = {};
  for (uint32_t i = 0; i < num_cells; ++i) ++start[level[i] + 1];
  for (int l = 1; l <= depth; ++l) start[l] += start[l - 1];
  auto b = std::make_shared<DecodedBrick>();
  b->cells.resize(num_cells);
  uint32_t payload = 0;
  for (uint32_t i = 0; i < num_cells; ++i) {
    const int l = level[i];
    uint32_t first;
    if (l == depth - 1) {
      first = payload;
      payload += Popcount8(masks[i]);
    } else {
      first = start[l + 1] + count[l + 1];
    }
    b->cells[start[l] + count[l]++] = MakeCompactCell(first, masks[i]);
  }
  const uint8_t* planes = raw + kBrickHeaderSize + num_cells;
  b->voxel_count = voxel_count;
  b->flags = flags;
  if (flags != kAttrDensity) {  // the value arrays, written straight
    b->attr_values.resize(n - kBrickHeaderSize - num_cells);  // left uninitialised
    UndeltaPlanes(planes, b->attr_values.data(), voxel_count, flags);
    if (flags & kAttrDensity) FindUniformBlocks(b.get(), depth, start, b->attr_values.data());
    return b;
  }
  // Densities alone are decoded into a scratch first: the blocks of one
  // density and the density most voxels share decide how the brick keeps
  // them (KeepAttributes).
  // (per thread, as the zstd scratch: at most one brick's values, given
  // back past 64 MiB)
  thread_local std::vector<uint8_t> values;
  struct Trim {
    ~Trim() {
      if (values.capacity() > (size_t(64) << 20)) std::vector<uint8_t>().swap(values);
    }
  } trim;
  if (values.size() < n - kBrickHeaderSize - num_cells) values.resize(n - kBrickHeaderSize - num_cells);
  UndeltaPlanes(planes, values.data(), voxel_count, flags);
  FindUniformBlocks(b.get(), depth, start, values.data());
  KeepAttributes(b.get(), values.data());
  return b;
}

namespace {

struct PoolValidator {
  const Cell* cells;
  size_t n;
  int depth;
  bool bricks;
  uint64_t limit;
  uint64_t next = 1;
  std::string error;

  bool Visit(uint64_t index, int level) {  // level: 0 for the root
    for (int d = 0; d < 8; ++d) {
      NodeRef r = cells[index].child[d];
      if (r == kEmptyRef) continue;
      if (level == depth - 1) {
        if (bricks) {
          if (!IsBrickRef(r) || (r & kBrickIdMask) >= limit) {
            error = "cell " + std::to_string(index) + " has ref " + std::to_string(r) +
                    " where a brick ref below " + std::to_string(limit) + " belongs";
            return false;
          }
        } else if (IsBrickRef(r) || LeafPayload(r) >= limit) {
          error = "cell " + std::to_string(index) + " has leaf ref " + std::to_string(r) +
                  " outside " + std::to_string(limit) + " payloads";
          return false;
        }
        continue;
      }
      if (IsBrickRef(r) || r != next || next >= n) {
        error = "cell " + std::to_string(index) + " refers to cell " + std::to_string(r) +
                " (expected " + std::to_string(next) + " of " + std::to_string(n) + ")";
        return false;
      }
      ++next;
      if (!Visit(r, level + 1)) return false;
    }
    return true;
  }
};

}  // namespace

Status ValidatePool(const Cell* cells, size_t n, int depth, bool bricks_at_last_level,
                    uint64_t limit) {
  if (n == 0) return CorruptionError("octree pool has no root cell");
  if (depth < 1 || depth > kMaxLevels) return CorruptionError("octree pool depth out of range");
  PoolValidator v{cells, n, depth, bricks_at_last_level, limit, 1, {}};
  if (!v.Visit(0, 0)) return CorruptionError("octree " + v.error);
  if (v.next != n)
    return CorruptionError("octree has " + std::to_string(n) + " cells but only " +
                           std::to_string(v.next) + " are reachable");
  return OkStatus();
}

Status ValidateLevelOrderPool(const CompactCell* cells, size_t n, int depth, uint64_t limit) {
  if (n == 0) return CorruptionError("octree pool has no root cell");
  if (depth < 1 || depth > kMaxLevels) return CorruptionError("octree pool depth out of range");
  uint64_t begin = 0, end = 1;  // the current level's cells
  for (int l = 0; l < depth; ++l) {
    const bool last = l == depth - 1;
    uint64_t children = 0;
    for (uint64_t i = begin; i < end; ++i) {
      const uint32_t mask = ChildMask(cells[i]);
      if (mask == 0) return CorruptionError("octree cell " + std::to_string(i) + " has no child");
      const uint64_t first = last ? children : end + children;
      if (FirstChild(cells[i]) != first)
        return CorruptionError("octree cell " + std::to_string(i) + " has first child " +
                               std::to_string(FirstChild(cells[i])) + ", expected " +
                               std::to_string(first));
      children += uint64_t(Popcount8(mask));
    }
    if (last) {
      if (children > limit)
        return CorruptionError("octree pool has " + std::to_string(children) +
                               " leaves, more than " + std::to_string(limit));
      if (end != n)
        return CorruptionError("octree has " + std::to_string(n) + " cells but only " +
                               std::to_string(end) + " are reachable");
      return OkStatus();
    }
    if (children > n - end)
      return CorruptionError("octree level " + std::to_string(l + 1) + " needs " +
                             std::to_string(children) + " cells past the pool's " +
                             std::to_string(n));
    begin = end;
    end += children;
  }
  return OkStatus();
}

}  // namespace vox::storage_internal

// Bricks and blocks of one density (brick_uniform.h).
#include "storage/internal/brick_uniform.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <mutex>
#include <span>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/octree.h"
#include "storage/internal/format.h"

namespace vox::storage_internal {

bool AllBytesAre(const uint8_t* p, size_t n, uint8_t byte) {
  const uint64_t want = uint64_t(byte) * 0x0101010101010101ull;
  uint64_t diff = 0;
  size_t i = 0;
#if defined(__SSE2__)
  // 64 bytes a step (a full brick's planes are 32^3 bytes each).
  const __m128i w = _mm_set1_epi8(char(byte));
  __m128i d = _mm_setzero_si128();
  for (; i + 64 <= n; i += 64) {
    const __m128i a = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i));
    const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i + 16));
    const __m128i c = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i + 32));
    const __m128i e = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + i + 48));
    d = _mm_or_si128(d, _mm_or_si128(_mm_or_si128(_mm_xor_si128(a, w), _mm_xor_si128(b, w)),
                                     _mm_or_si128(_mm_xor_si128(c, w), _mm_xor_si128(e, w))));
  }
  if (_mm_movemask_epi8(_mm_cmpeq_epi8(d, _mm_setzero_si128())) != 0xffff) return false;
#endif
  for (; i + 8 <= n; i += 8) {
    uint64_t v;
    std::memcpy(&v, p + i, 8);
    diff |= v ^ want;
  }
  for (; i < n; ++i) diff |= uint64_t(p[i] ^ byte);
  return diff == 0;
}

void FindUniformBlocks(DecodedBrick* b, int depth, const uint32_t* level_start, const uint8_t* values) {
  const uint32_t n = uint32_t(b->cells.size());
  const size_t count = b->voxel_count;
  // The densities: `count` 4-byte values (the value arrays, brick_codec.h).
  const uint8_t* d = DensityBytes(values, b->voxel_count, b->flags, 0);
  // (A brick deeper than 10 levels cannot be full: its voxel count is 32-bit.)
  if (depth <= 10 && uint64_t(count) == uint64_t(1) << (3 * depth)) {
    // A full brick (the inside of a fog): of one density when the array
    // equals itself shifted by one value.
    const bool same = std::memcmp(d, d + 4, 4 * (count - 1)) == 0;
    const float f = same ? ReadDensity(values, b->voxel_count, b->flags, 0) : -1.0f;
    if (f >= 0 && std::isfinite(f)) {
      b->uniform_density = f;
      return;
    }
  }
  // Bottom-up: each full cell's one density (its bits), or kMixed.
  constexpr uint32_t kMixed = 0xffffffffu;  // (a NaN's bits: never a block's density)
  thread_local std::vector<uint32_t> one;
  thread_local std::vector<int8_t> levels;  // per cell: its block's levels, or -1
  one.assign(n, kMixed);
  auto same8 = [](const uint8_t* p) {  // the 8 values at p are one
    uint64_t v[4];
    std::memcpy(v, p, sizeof v);
    return v[0] == v[1] && v[0] == v[2] && v[0] == v[3] && uint32_t(v[0]) == uint32_t(v[0] >> 32);
  };
  bool any = false;
  for (uint32_t i = level_start[depth - 1]; i < level_start[depth]; ++i) {
    // A last-level cell's 8 voxels are payloads first..first+7.
    const CompactCell c = b->cells[i];
    if (ChildMask(c) != 0xffu) continue;
    const uint32_t first = c.bits >> 8;
    const uint8_t* p = d + size_t(4) * first;
    if (!same8(p)) continue;
    const uint32_t bits = uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
    const float f = std::bit_cast<float>(bits);
    if (!(f >= 0 && std::isfinite(f))) continue;
    one[i] = bits;
    any = true;
  }
  if (!any) return;  // (no block of 2^3: none larger either)
  for (int l = depth - 2; l >= 0; --l)
    for (uint32_t i = level_start[l]; i < level_start[l + 1]; ++i) {
      const CompactCell c = b->cells[i];
      if (ChildMask(c) != 0xffu) continue;
      const uint32_t first = c.bits >> 8, d = one[first];
      bool same = d != kMixed;
      for (uint32_t k = 1; k < 8 && same; ++k) same = one[first + k] == d;
      if (same) one[i] = d;
    }
  if (one[0] != kMixed) {  // the root: the whole brick
    b->uniform_density = std::bit_cast<float>(one[0]);
    return;
  }
  // Top-down: a cell in a block of one density takes the largest such
  // block's levels. Such a cell is full, as all its descendants are.
  levels.assign(n, -1);
  b->uniform_levels.assign((count + 1) / 2, uint8_t(DecodedBrick::kNotUniform * 0x11));
  for (int l = 0; l < depth; ++l)
    for (uint32_t i = level_start[l]; i < level_start[l + 1]; ++i) {
      const int8_t mine = levels[i] >= 0 ? levels[i] : one[i] != kMixed ? int8_t(depth - l) : int8_t(-1);
      if (mine < 0) continue;
      const uint32_t first = b->cells[i].bits >> 8;
      if (l < depth - 1) {
        std::memset(&levels[first], mine, 8);
      } else {
        // (a last-level cell's 8 voxels, half a byte each, from payload first)
        const uint8_t half = uint8_t(std::min<int>(mine, DecodedBrick::kMaxUniformLevels));
        uint8_t* at = &b->uniform_levels[first >> 1];
        if ((first & 1) == 0) {
          std::memset(at, half * 0x11, 4);
        } else {
          at[0] = uint8_t((at[0] & 0x0f) | half << 4);
          std::memset(at + 1, half * 0x11, 3);
          at[4] = uint8_t((at[4] & 0xf0) | half);
        }
      }
    }
}

void KeepAttributes(DecodedBrick* b, const uint8_t* values) {
  const uint32_t count = b->voxel_count;
  const size_t bytes = size_t(count) * AttrBytesPerVoxel(b->flags);
  auto copy = [&] { b->attr_values.assign(values, values + bytes); };
  if (b->flags != kAttrDensity || b->uniform_levels.empty() || b->uniform_density >= 0) return copy();
  // The candidate: the density of the first voxel in a block of one density.
  uint32_t first = 0;
  while (first < count && b->UniformLevelsOf(first) < 0) ++first;
  if (first == count) return copy();
  uint32_t want;  // (its bytes as the host reads them: only compared)
  std::memcpy(&want, values + size_t(4) * first, 4);
  const size_t words = (size_t(count) + 63) / 64;
  b->common_words.resize(words);
  uint64_t others = 0;
  for (size_t w = 0; w < words; ++w) {
    const uint32_t p0 = uint32_t(w * 64), n = std::min<uint32_t>(64, count - p0);
    const uint8_t* v = values + size_t(4) * p0;
    uint64_t bits = 0;
    uint32_t k = 0;
#if defined(__SSE2__)
    const __m128i cand = _mm_set1_epi32(int32_t(want));
    for (; k + 4 <= n; k += 4) {
      const __m128i x = _mm_loadu_si128(reinterpret_cast<const __m128i*>(v + size_t(4) * k));
      bits |= uint64_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(x, cand)))) << k;
    }
#endif
    for (; k < n; ++k) {
      uint32_t x;
      std::memcpy(&x, v + size_t(4) * k, 4);
      bits |= uint64_t(x == want) << k;
    }
    b->common_words[w] = DecodedBrick::CommonWord{bits, others};
    others += n - uint32_t(std::popcount(bits));
  }
  // Worth it where at least half the voxels are common and the two arrays
  // fit the one block the plain form takes (DecodedBrick::MaxCharge).
  if (2 * others > count ||
      BufferPool::BlockSize(4 * others) + BufferPool::BlockSize(words * sizeof(DecodedBrick::CommonWord)) >
          BufferPool::BlockSize(bytes)) {
    decltype(b->common_words)().swap(b->common_words);
    return copy();
  }
  b->common = true;
  b->common_density = ReadDensity(values, count, b->flags, first);
  b->attr_values.resize(4 * others);  // (written whole below)
  uint8_t* out = b->attr_values.data();
  for (size_t w = 0; w < words; ++w) {
    const uint32_t p0 = uint32_t(w * 64), n = std::min<uint32_t>(64, count - p0);
    uint64_t rest = ~b->common_words[w].bits & (n == 64 ? ~uint64_t(0) : (uint64_t(1) << n) - 1);
    for (; rest != 0; rest &= rest - 1, out += 4)
      std::memcpy(out, values + size_t(4) * (p0 + uint32_t(std::countr_zero(rest))), 4);
  }
}

std::span<const CompactCell> FullPool(int depth) {
  static std::once_flag once[kMaxFullPoolDepth + 1];
  static std::vector<CompactCell> pools[kMaxFullPoolDepth + 1];
  if (depth < 1 || depth > kMaxFullPoolDepth) return {};
  std::call_once(once[depth], [depth] {
    std::vector<CompactCell>& pool = pools[depth];
    // Level l holds 8^l cells from start = (8^l - 1) / 7; cell j's children
    // are cells (or, at the last level, payloads) 8j..8j+7 of the next.
    for (int l = 0; l < depth; ++l) {
      const uint32_t cells = uint32_t(1) << (3 * l), next = (uint32_t(1) << (3 * (l + 1))) / 7;
      for (uint32_t j = 0; j < cells; ++j)
        pool.push_back(MakeCompactCell(l == depth - 1 ? 8 * j : next + 8 * j, 0xffu));
    }
  });
  return pools[depth];
}

std::shared_ptr<DecodedBrick> DecodeFullOfOne(const uint8_t* masks, uint32_t num_cells,
                                              const uint8_t* planes, uint32_t voxel_count,
                                              int depth, uint8_t flags) {
  if (depth > kMaxFullPoolDepth || voxel_count != uint32_t(1) << (3 * depth)) return nullptr;
  const std::span<const CompactCell> pool = FullPool(depth);
  if (num_cells != pool.size() || !AllBytesAre(masks, num_cells, 0xff)) return nullptr;
  const size_t bytes = AttrBytesPerVoxel(flags);
  for (size_t k = 0; k < bytes; ++k)
    if (!AllBytesAre(planes + k * voxel_count + 1, voxel_count - 1, 0)) return nullptr;
  uint8_t voxel[kMaxAttrBytesPerVoxel];
  for (size_t k = 0; k < bytes; ++k) voxel[k] = planes[k * voxel_count];  // (one voxel's planes are its value arrays)
  return FullOfOneBrick(voxel, voxel_count, depth, flags);
}

std::shared_ptr<DecodedBrick> FullOfOneBrick(const uint8_t* voxel, uint32_t voxel_count, int depth,
                                             uint8_t flags) {
  const std::span<const CompactCell> pool = FullPool(depth);
  const size_t bytes = AttrBytesPerVoxel(flags);
  auto b = std::make_shared<DecodedBrick>();
  b->full_of_one = true;
  b->shared_cells = pool.data();
  b->shared_cell_count = uint32_t(pool.size());
  b->attr_values.assign(voxel, voxel + bytes);
  b->voxel_count = voxel_count;
  b->flags = flags;
  if (flags & kAttrDensity) {
    const float d = ReadDensity(b->attr_values.data(), 1, flags, 0);
    if (d >= 0 && std::isfinite(d)) b->uniform_density = d;
  }
  return b;
}

}  // namespace vox::storage_internal

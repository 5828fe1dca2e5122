// The brick codec of vox's store format: the decompressed contents of a
// brick record (FORMAT.md, "Brick record"): header, child masks, planar
// attributes with octahedral normals and delta-coded planes; the decoded
// brick the cache holds; and the checks of cell pools read from disk.
// Private to storage and its tests. Stateless functions; thread-safe.
#ifndef VOX_STORAGE_INTERNAL_BRICK_CODEC_H_
#define VOX_STORAGE_INTERNAL_BRICK_CODEC_H_

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "core/octree.h"
#include "core/util/status.h"
#include "storage/buffer_pool.h"
#include "storage/internal/format.h"
#include "storage/meta.h"

namespace vox::storage_internal {

// The most cells a `depth`-level pool over `voxels` voxels can have:
// sum over levels l < depth of min(8^l, voxels). Zero when voxels exceed 8^depth.
uint64_t MaxCells(int depth, uint64_t voxels);

// Octahedral normal in 2 x 16 bits (u | v << 16), each a multiple of
// 2^(16 - bits). A zero or non-finite vector encodes as +z.
uint32_t EncodeOctNormal(const glm::vec3& n, int bits = 16);
glm::vec3 DecodeOctNormal(uint32_t code);

// Coverage as a 16-bit fraction: round(c * 65535), at least 1 (an occupied
// cell is never empty); decoded as q / 65535.
inline uint16_t EncodeCoverage(float c) {
  if (!(c > 0)) return 1;  // an occupied cell has some coverage
  return c >= 1 ? 65535 : uint16_t(std::clamp(std::lround(double(c) * 65535.0), 1L, 65535L));
}
inline float DecodeCoverage(uint16_t q) { return float(q) / 65535.0f; }

// The attributes as a decoded brick and a store's resident top hold them
// ("value arrays"): for each attribute component in plane order (normal u
// and v, density, colour r g b, coverage, temperature: 2 or 4 bytes each),
// an array of `count` little-endian values. The same bytes as the planar
// form of the file, regrouped so that one voxel's value lies in one place:
// fog reads a density per cell it crosses, one cache line instead of four.
//
// A voxel's attributes from value arrays of `count` voxels.
VoxelAttributes ReadAttributes(const uint8_t* values, uint32_t count, uint8_t flags,
                               uint32_t index);
// Where the same voxel's density lies (with kAttrDensity).
inline const uint8_t* DensityBytes(const uint8_t* values, uint32_t count, uint8_t flags, uint32_t index) {
  return values + ((flags & kAttrNormal) ? size_t(4) * count : 0) + size_t(4) * index;
}
// The same voxel's density alone (0 without kAttrDensity).
inline float ReadDensity(const uint8_t* values, uint32_t count, uint8_t flags, uint32_t index) {
  if (!(flags & kAttrDensity)) return 0.0f;
  const uint8_t* p = DensityBytes(values, count, flags, index);
  const uint32_t bits = uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
  return std::bit_cast<float>(bits);
}
// The value arrays of planar attribute bytes (`count` voxels, as the file
// holds them without delta coding: a top-only store's attributes).
std::vector<uint8_t> PlanesToValues(std::span<const uint8_t> planes, uint32_t count, uint8_t flags);
// Appends the planar attribute bytes of `attrs` (in payload order).
void WriteAttributes(std::span<const VoxelAttributes> attrs, uint8_t flags, std::string* dst,
                     int normal_bits = 16);

// The decompressed contents of a brick: header, one child mask per cell in
// pre-order, planar attributes. `cells` is a BuildCells pool (pre-order).
std::string EncodeBrickRaw(std::span<const Cell> cells, std::span<const VoxelAttributes> attrs,
                           int depth, uint8_t flags, int normal_bits = 16);

// A decoded brick as the cache holds it: its pool in traversal form.
struct DecodedBrick {
  // Both arrays live in the process's brick pool (storage/buffer_pool.h)
  // when one is reserved, else on the heap.
  std::vector<CompactCell, BrickAllocator<CompactCell>> cells;
  // The attributes as value arrays (ReadAttributes). Written whole by
  // DecodeBrickRaw straight from the decompressed record's planes (delta
  // decoding and regrouping in one pass), so never zeroed first.
  std::vector<uint8_t, BrickAllocator<uint8_t>> attr_values;
  uint32_t voxel_count = 0;
  uint8_t flags = 0;
  // Every voxel of the brick's grid occupied, all of one density (the
  // inside of a fog volume): that density, else -1. A ray crosses such a
  // brick as one cell.
  float uniform_density = -1.0f;
  // Every voxel of the brick's grid occupied, all with voxel 0's attributes
  // (the inside of a fog volume, made from a level set or of one
  // temperature): attr_values holds that one voxel, and `cells` is empty,
  // the pool being FullPool(depth), shared by all such bricks.
  bool full_of_one = false;
  const CompactCell* shared_cells = nullptr;
  uint32_t shared_cell_count = 0;

  // A brick whose one attribute is density, most of its voxels of one
  // density though not all (the inside of a fog beside its rim, in a brick
  // the rim crosses): `common` set, that density in common_density, and
  // attr_values holds only the other voxels' densities, in payload order;
  // per 64 voxels (payload order), a bit for each voxel of the common
  // density and the count of the other voxels before them. A fog's rim
  // bricks then take a fraction of the memory, and the densities a ray
  // reads there mostly come from the small bit array.
  struct CommonWord {
    uint64_t bits;    // voxel 64 w + k is of the common density when bit k is set
    uint64_t before;  // the other voxels before voxel 64 w
  };
  bool common = false;
  float common_density = 0.0f;
  std::vector<CommonWord, BrickAllocator<CommonWord>> common_words;

  // The cell pool in traversal form, and the attributes of payload p
  // (DensityOf, AttributesOf; else ReadDensity and ReadAttributes read
  // attr_values with AttrCount() and AttrIndex(p)).
  const CompactCell* CellData() const { return full_of_one ? shared_cells : cells.data(); }
  uint32_t CellCount() const { return full_of_one ? shared_cell_count : uint32_t(cells.size()); }
  uint32_t AttrCount() const { return full_of_one ? 1u : voxel_count; }
  uint32_t AttrIndex(uint32_t payload) const { return full_of_one ? 0u : payload; }
  // Where payload p's density lies in attr_values' bytes, or null when it is
  // the common density (payload < voxel_count; a brick with densities).
  const uint8_t* DensityPlace(uint32_t payload) const {
    if (common) {
      const CommonWord& w = common_words[payload >> 6];
      const uint64_t bit = uint64_t(1) << (payload & 63);
      if (w.bits & bit) return nullptr;
      return attr_values.data() + size_t(4) * (w.before + uint64_t(std::popcount(~w.bits & (bit - 1))));
    }
    return DensityBytes(attr_values.data(), AttrCount(), flags, AttrIndex(payload));
  }
  float DensityOf(uint32_t payload) const {
    const uint8_t* p = DensityPlace(payload);
    if (p == nullptr) return common_density;
    const uint32_t bits = uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
    return std::bit_cast<float>(bits);
  }
  VoxelAttributes AttributesOf(uint32_t payload) const {
    if (!common) return ReadAttributes(attr_values.data(), AttrCount(), flags, AttrIndex(payload));
    const float d = DensityOf(payload);  // (the one attribute)
    uint8_t one[4];
    const uint32_t bits = std::bit_cast<uint32_t>(d);
    for (int k = 0; k < 4; ++k) one[k] = uint8_t(bits >> (8 * k));
    return ReadAttributes(one, 1, flags, 0);
  }
  // Otherwise, for bricks with densities: per voxel (payload order, half a
  // byte each: voxel p in the low half of byte p / 2 when p is even), the
  // levels of the largest aligned block around it (2^levels voxels a side,
  // within the brick, at most kMaxUniformLevels: a block inside a larger
  // one is as uniform) whose voxels are all occupied and of one density, or
  // kNotUniform; empty when the brick has no such block of 2^3 voxels.
  std::vector<uint8_t, BrickAllocator<uint8_t>> uniform_levels;
  static constexpr uint8_t kNotUniform = 0xf;
  static constexpr int kMaxUniformLevels = 14;
  // Payload p's levels (UniformLevelsOf: -1 where it is in no such block).
  int UniformLevelsOf(uint32_t payload) const {
    if (uniform_levels.empty()) return -1;
    const uint8_t l = (uniform_levels[payload >> 1] >> ((payload & 1) * 4)) & 0xf;
    return l == kNotUniform ? -1 : int(l);
  }
  // What it costs in memory: this struct, its two blocks (a pool block's
  // whole size, or the heap block's capacity), and the shared_ptr control
  // block make_shared puts beside it. (The cache adds its own per-entry
  // overhead; see ShardedPageCache.)
  size_t charge() const {
    return sizeof(DecodedBrick) +
           (cells.empty() ? 0 : BrickBlockBytes(cells.data(), cells.capacity() * sizeof(CompactCell))) +
           BrickBlockBytes(attr_values.data(), attr_values.capacity()) +
           (uniform_levels.empty() ? 0 : BrickBlockBytes(uniform_levels.data(), uniform_levels.capacity())) +
           (common_words.empty() ? 0 : BrickBlockBytes(common_words.data(), common_words.capacity() * sizeof(CommonWord))) +
           kOverheadBytes;
  }
  // The most charge() can be for a brick of `cells` cells, `attr_bytes`
  // attribute bytes and `voxels` voxels with densities (all arrays in pool
  // blocks; a brick of a common density takes its two arrays only where
  // they fit the one block of attr_bytes).
  static size_t MaxCharge(uint64_t cells, uint64_t attr_bytes, uint64_t density_voxels) {
    return sizeof(DecodedBrick) + BufferPool::BlockSize(cells * sizeof(CompactCell)) +
           BufferPool::BlockSize(attr_bytes) +
           (density_voxels > 0 ? BufferPool::BlockSize(density_voxels) : 0) + kOverheadBytes;
  }
  static constexpr size_t kOverheadBytes = 16 + 3 * 16 + 64 + 8 + 32;
};

// The traversal-form pool of a brick of `depth` levels whose every cell is
// occupied (all masks 0xff), built once per depth and kept for the
// process's life; depth at most kMaxFullPoolDepth.
inline constexpr int kMaxFullPoolDepth = 6;
std::span<const CompactCell> FullPool(int depth);

// Rebuilds the cell pool (level order, as LevelOrderPool would make it from
// the BuildCells pool) from raw brick bytes, checking every field against
// the table row and the store's depth and flags. The pool is valid by
// construction: indices in range, leaves exactly at depth. A full brick of
// depth at most kMaxFullPoolDepth whose voxels all have one value decodes
// as full_of_one.
// Errors are Corruption without a file name (the caller adds it).
StatusOr<std::shared_ptr<DecodedBrick>> DecodeBrickRaw(const uint8_t* raw, size_t n,
                                                       const BrickEntry& entry, int depth,
                                                       uint8_t flags);

// Checks a `depth`-level pool laid out as BuildCells does (pre-order): each
// cell ref is the next index in pre-order and every cell is reached once;
// refs at the last level are brick refs < limit (bricks_at_last_level) or
// leaf refs with payload < limit. Linear time; never reads out of bounds.
Status ValidatePool(const Cell* cells, size_t n, int depth, bool bricks_at_last_level,
                    uint64_t limit);

// Checks a `depth`-level traversal-form (level-order) pool of `n` cells:
// every cell has a child, each level's cells are the previous level's
// children in order (each first index is where the cell's children begin),
// every cell is reached once, and the last level's children number at most
// `limit` payloads. Linear time; never reads out of bounds.
Status ValidateLevelOrderPool(const CompactCell* cells, size_t n, int depth, uint64_t limit);

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_BRICK_CODEC_H_

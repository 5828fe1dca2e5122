// The constants, on-disk records and brick codec of vox's store format
// (storage/FORMAT.md is the specification; keep the two in step). Private to
// storage and its tests. Stateless functions and immutable values; thread-safe.
#ifndef VOX_STORAGE_INTERNAL_FORMAT_H_
#define VOX_STORAGE_INTERNAL_FORMAT_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/octree.h"
#include "core/status.h"
#include "storage/store.h"

namespace vox::storage_internal {

// "VOXINDEX" and "VOXBRICK" read as little-endian fixed64.
inline constexpr uint64_t kIndexMagic = 0x5845444e49584f56ull;
inline constexpr uint64_t kBrickMagic = 0x4b43495242584f56ull;
inline constexpr uint16_t kFormatMajor = 1;
inline constexpr uint16_t kFormatMinor = 1;
inline constexpr char kIndexFileName[] = "index.vxi";
inline constexpr char kBrickFileName[] = "bricks.vxb";
inline constexpr char kLodDirName[] = "lod";  // the level-of-detail pyramid (storage/lod.h)

inline constexpr size_t kFileHeaderSize = 32;  // both files
inline constexpr size_t kFooterSize = 96;      // index file
inline constexpr size_t kTrailerSize = 5;      // codec byte + masked CRC32C
inline constexpr size_t kTableEntrySize = 56;
inline constexpr size_t kBrickHeaderSize = 16;  // inside a brick's decompressed bytes
// No brick decompresses to more than this (a sanity bound on untrusted sizes).
inline constexpr uint64_t kMaxBrickRawBytes = uint64_t(1) << 30;

enum Codec : uint8_t { kCodecRaw = 0, kCodecZstd = 1 };

// Attribute flags (brick header byte 9 and meta block).
inline constexpr uint8_t kAttrNormal = 1, kAttrDensity = 2, kAttrColor = 4, kAttrCoverage = 8;
inline constexpr uint8_t kAttrAll = kAttrNormal | kAttrDensity | kAttrColor | kAttrCoverage;
uint8_t AttrFlags(const StoreMeta& meta);
// Bytes per voxel of the attributes `flags` selects.
size_t AttrBytesPerVoxel(uint8_t flags);

// The 32-byte header both files open with.
struct FileHeader {
  uint64_t magic = 0;
  uint16_t major = 0, minor = 0;
  uint64_t store_id = 0;
};
std::string EncodeFileHeader(uint64_t magic, uint64_t store_id);
// Checks magic, CRC and major version. `path` names the file in errors.
StatusOr<FileHeader> DecodeFileHeader(const uint8_t* p, uint64_t expected_magic,
                                      const std::string& path);

// Where a block lies in the index file: offset and size without trailer.
struct BlockHandle {
  uint64_t offset = 0, size = 0;
};

struct Footer {
  BlockHandle meta, top, top_attr, table;
  uint64_t brick_file_size = 0;
  uint64_t store_id = 0;
  uint16_t major = kFormatMajor, minor = kFormatMinor;
};
std::string EncodeFooter(const Footer& f);
StatusOr<Footer> DecodeFooter(const uint8_t* p, const std::string& path);

// A block is followed by its trailer: codec byte + masked CRC32C of block and codec.
std::string BlockTrailer(const void* data, size_t n, uint8_t codec);
// Verifies the trailer at data[n, n + 5); returns the codec.
StatusOr<uint8_t> CheckTrailer(const uint8_t* data, size_t n, const std::string& what,
                               const std::string& path, uint64_t offset);

std::string EncodeMeta(const StoreMeta& m);
StatusOr<StoreMeta> DecodeMeta(const uint8_t* p, size_t n, const std::string& path);

// One brick table row (FORMAT.md, "Brick table").
struct BrickEntry {
  uint64_t offset = 0;          // of the record in the brick file
  uint64_t x = 0, y = 0, z = 0; // brick coordinate (grid >> (levels - brick_level))
  uint32_t stored_size = 0;     // zstd frame bytes (record is stored_size + 5)
  uint32_t raw_size = 0;        // decompressed bytes
  uint32_t num_cells = 0;
  uint32_t voxel_count = 0;
  uint32_t crc = 0;             // masked CRC32C of frame + codec, as in the record
  uint8_t codec = kCodecZstd;
};
void EncodeBrickEntry(const BrickEntry& e, std::string* dst);
BrickEntry DecodeBrickEntry(const uint8_t* p);

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

// A voxel's attributes from planar attribute bytes (`count` voxels).
VoxelAttributes ReadAttributes(const uint8_t* planes, uint32_t count, uint8_t flags,
                               uint32_t index);
// Appends the planar attribute bytes of `attrs` (in payload order).
void WriteAttributes(std::span<const VoxelAttributes> attrs, uint8_t flags, std::string* dst,
                     int normal_bits = 16);

// The decompressed contents of a brick: header, one child mask per cell in
// pre-order, planar attributes. `cells` is a BuildCells pool (pre-order).
std::string EncodeBrickRaw(std::span<const Cell> cells, std::span<const VoxelAttributes> attrs,
                           int depth, uint8_t flags, int normal_bits = 16);

// A decoded brick as the cache holds it: its pool in traversal form.
struct DecodedBrick {
  std::vector<CompactCell> cells;
  std::vector<uint8_t> attr_planes;
  uint32_t voxel_count = 0;
  uint8_t flags = 0;
  // What it costs in memory: this struct, its two heap blocks (capacity, as
  // allocated), and the shared_ptr control block make_shared puts beside it.
  // (The cache adds its own per-entry overhead; see ShardedPageCache.)
  size_t charge() const {
    return sizeof(DecodedBrick) + cells.capacity() * sizeof(CompactCell) +
           attr_planes.capacity() + kOverheadBytes;
  }
  // Bookkeeping beside the data: the shared_ptr control block make_shared
  // puts in front of this struct (16), a malloc header on each of the three
  // allocations (3 x 16), and the cache's entry: a hash-map node holding the
  // key, the shared_ptr, the charge and the LRU iterator (64 with the malloc
  // header), its bucket pointer (8), and the LRU list node (32).
  static constexpr size_t kOverheadBytes = 16 + 3 * 16 + 64 + 8 + 32;
};

// Rebuilds the cell pool (level order, as LevelOrderPool would make it from
// the BuildCells pool) from raw brick bytes, checking every field against
// the table row and the store's depth and flags. The pool is valid by
// construction: indices in range, leaves exactly at depth.
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

#endif  // VOX_STORAGE_INTERNAL_FORMAT_H_

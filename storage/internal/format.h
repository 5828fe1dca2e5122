// The constants and on-disk records of vox's store format: file header,
// footer, block trailers, metadata block and brick table rows
// (storage/FORMAT.md is the specification; keep the two in step). The brick
// codec is storage/internal/brick_codec.h. Private to storage and its tests.
// Stateless functions and immutable values; thread-safe.
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
#include "core/util/status.h"
#include "storage/meta.h"

namespace vox::storage_internal {

// "VOXINDEX" and "VOXBRICK" read as little-endian fixed64.
inline constexpr uint64_t kIndexMagic = 0x5845444e49584f56ull;
inline constexpr uint64_t kBrickMagic = 0x4b43495242584f56ull;
inline constexpr uint16_t kFormatMajor = 1;
inline constexpr uint16_t kFormatMinor = 3;
inline constexpr char kIndexFileName[] = "index.vxi";
inline constexpr char kBrickFileName[] = "bricks.vxb";
inline constexpr char kLodDirName[] = "lod";  // the level-of-detail pyramid (storage/lod.h)
// A resumable ingest's journal (brick_journal.h): a directory holding one is
// an unfinished ingest, never opened as a store.
inline constexpr char kJournalFileName[] = "journal";

inline constexpr size_t kFileHeaderSize = 32;  // both files
inline constexpr size_t kFooterSize = 96;      // index file
inline constexpr size_t kTrailerSize = 5;      // codec byte + masked CRC32C
inline constexpr size_t kTableEntrySize = 56;
inline constexpr size_t kBrickHeaderSize = 16;  // inside a brick's decompressed bytes
// No brick decompresses to more than this (a sanity bound on untrusted sizes).
inline constexpr uint64_t kMaxBrickRawBytes = uint64_t(1) << 30;

enum Codec : uint8_t { kCodecRaw = 0, kCodecZstd = 1 };

// Attribute flags (brick header byte 9 and meta block).
inline constexpr uint8_t kAttrNormal = 1, kAttrDensity = 2, kAttrColor = 4, kAttrCoverage = 8,
                          kAttrTemperature = 16;  // 1.3
inline constexpr uint8_t kAttrAll =
    kAttrNormal | kAttrDensity | kAttrColor | kAttrCoverage | kAttrTemperature;
uint8_t AttrFlags(const StoreMeta& meta);
// Bytes per voxel of the attributes `flags` selects.
size_t AttrBytesPerVoxel(uint8_t flags);
// Its largest value (every attribute: AttrBytesPerVoxel(kAttrAll)).
inline constexpr size_t kMaxAttrBytesPerVoxel = 20;

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

// Format 1.2 appends to the metadata what a reader needs to page the brick
// table in on demand instead of reading it whole at open (FORMAT.md, "Brick
// table pages"): the largest row values and a CRC per page of rows.
inline constexpr uint32_t kTablePageRows = 1024;
inline constexpr uint32_t kMaxTablePageRows = uint32_t(1) << 20;
struct TableSummary {
  uint32_t page_rows = 0;  // rows per page; 0: absent (a 1.0 or 1.1 store)
  uint32_t max_stored_size = 0, max_num_cells = 0, max_voxel_count = 0;
  uint64_t sum_num_cells = 0;
  std::vector<uint32_t> page_crcs;  // masked CRC32C of each page's encoded rows
  size_t pages(uint64_t rows) const { return page_rows ? (rows + page_rows - 1) / page_rows : 0; }
};

// `summary` (page_rows != 0) is appended as the 1.2 fields.
std::string EncodeMeta(const StoreMeta& m, const TableSummary& summary = {});
// Fills `summary` (when not null) from the 1.2 fields, page_rows 0 when absent.
StatusOr<StoreMeta> DecodeMeta(const uint8_t* p, size_t n, const std::string& path,
                               TableSummary* summary = nullptr);

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

// The summary of brick table `rows`, whose encoded bytes are `table`.
TableSummary SummarizeTable(const std::vector<BrickEntry>& rows, const std::string& table,
                            uint32_t page_rows = kTablePageRows);
// The masked CRC32C of one page's encoded rows (`n` bytes at `p`).
uint32_t TablePageCrc(const uint8_t* p, size_t n);

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_FORMAT_H_

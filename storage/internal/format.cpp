#include "storage/internal/format.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <glm/gtc/packing.hpp>

#include "core/util/crc32c.h"
#include "storage/internal/coding.h"
#include "storage/meta_check.h"

namespace vox::storage_internal {
namespace {

std::string Hex(uint64_t v) {
  char b[24];
  snprintf(b, sizeof(b), "0x%016llx", static_cast<unsigned long long>(v));
  return b;
}

Status VersionCheck(uint16_t major, uint16_t minor, const std::string& path) {
  if (major != kFormatMajor)
    return UnsupportedError("'" + path + "' has store format " + std::to_string(major) + "." +
                            std::to_string(minor) + "; this vox reads format " +
                            std::to_string(kFormatMajor) + ".x");
  return OkStatus();
}

}  // namespace

uint8_t AttrFlags(const StoreMeta& m) {
  return uint8_t((m.has_normal ? kAttrNormal : 0) | (m.has_density ? kAttrDensity : 0) |
                 (m.has_color ? kAttrColor : 0) | (m.has_coverage ? kAttrCoverage : 0) |
                 (m.has_temperature ? kAttrTemperature : 0));
}

size_t AttrBytesPerVoxel(uint8_t flags) {
  return ((flags & kAttrNormal) ? 4 : 0) + ((flags & kAttrDensity) ? 4 : 0) +
         ((flags & kAttrColor) ? 6 : 0) + ((flags & kAttrCoverage) ? 2 : 0) +
         ((flags & kAttrTemperature) ? 4 : 0);
}

std::string EncodeFileHeader(uint64_t magic, uint64_t store_id) {
  uint8_t b[kFileHeaderSize] = {};
  EncodeFixed64(b, magic);
  EncodeFixed16(b + 8, kFormatMajor);
  EncodeFixed16(b + 10, kFormatMinor);
  EncodeFixed64(b + 16, store_id);
  EncodeFixed32(b + 28, crc32c::Mask(crc32c::Value(b, 28)));
  return std::string(reinterpret_cast<char*>(b), sizeof(b));
}

StatusOr<FileHeader> DecodeFileHeader(const uint8_t* p, uint64_t expected_magic,
                                      const std::string& path) {
  FileHeader h;
  h.magic = DecodeFixed64(p);
  if (h.magic != expected_magic)
    return CorruptionError("'" + path + "' is not a vox store file: bad magic " + Hex(h.magic) +
                           " (expected " + Hex(expected_magic) + ")");
  if (crc32c::Unmask(DecodeFixed32(p + 28)) != crc32c::Value(p, 28))
    return CorruptionError("'" + path + "': header checksum mismatch");
  h.major = DecodeFixed16(p + 8);
  h.minor = DecodeFixed16(p + 10);
  VOX_RETURN_IF_ERROR(VersionCheck(h.major, h.minor, path));
  h.store_id = DecodeFixed64(p + 16);
  return h;
}

std::string EncodeFooter(const Footer& f) {
  uint8_t b[kFooterSize] = {};
  const BlockHandle* hs[4] = {&f.meta, &f.top, &f.top_attr, &f.table};
  for (int i = 0; i < 4; ++i) {
    EncodeFixed64(b + 16 * i, hs[i]->offset);
    EncodeFixed64(b + 16 * i + 8, hs[i]->size);
  }
  EncodeFixed64(b + 64, f.brick_file_size);
  EncodeFixed64(b + 72, f.store_id);
  EncodeFixed16(b + 80, f.major);
  EncodeFixed16(b + 82, f.minor);
  EncodeFixed64(b + 84, kIndexMagic);
  EncodeFixed32(b + 92, crc32c::Mask(crc32c::Value(b, 92)));
  return std::string(reinterpret_cast<char*>(b), sizeof(b));
}

StatusOr<Footer> DecodeFooter(const uint8_t* b, const std::string& path) {
  uint64_t magic = DecodeFixed64(b + 84);
  if (magic != kIndexMagic)
    return CorruptionError("'" + path + "': bad footer magic " + Hex(magic) +
                           " (file truncated or not a vox store index)");
  if (crc32c::Unmask(DecodeFixed32(b + 92)) != crc32c::Value(b, 92))
    return CorruptionError("'" + path + "': footer checksum mismatch");
  Footer f;
  f.major = DecodeFixed16(b + 80);
  f.minor = DecodeFixed16(b + 82);
  VOX_RETURN_IF_ERROR(VersionCheck(f.major, f.minor, path));
  BlockHandle* hs[4] = {&f.meta, &f.top, &f.top_attr, &f.table};
  for (int i = 0; i < 4; ++i) {
    hs[i]->offset = DecodeFixed64(b + 16 * i);
    hs[i]->size = DecodeFixed64(b + 16 * i + 8);
  }
  f.brick_file_size = DecodeFixed64(b + 64);
  f.store_id = DecodeFixed64(b + 72);
  return f;
}

std::string BlockTrailer(const void* data, size_t n, uint8_t codec) {
  uint32_t crc = crc32c::Extend(crc32c::Value(data, n), &codec, 1);
  uint8_t t[kTrailerSize];
  t[0] = codec;
  EncodeFixed32(t + 1, crc32c::Mask(crc));
  return std::string(reinterpret_cast<char*>(t), kTrailerSize);
}

StatusOr<uint8_t> CheckTrailer(const uint8_t* data, size_t n, const std::string& what,
                               const std::string& path, uint64_t offset) {
  uint8_t codec = data[n];
  uint32_t crc = crc32c::Extend(crc32c::Value(data, n), &codec, 1);
  if (crc32c::Unmask(DecodeFixed32(data + n + 1)) != crc)
    return CorruptionError("'" + path + "': " + what + " checksum mismatch (block at offset " +
                           std::to_string(offset) + ", " + std::to_string(n) + " bytes)");
  return codec;
}

std::string EncodeMeta(const StoreMeta& m, const TableSummary& t) {
  std::string s;
  PutString(&s, m.source_file);
  PutString(&s, m.grid_name);
  s.push_back(char(m.grid_class));
  s.push_back(char(m.levels));
  s.push_back(char(m.brick_level));
  s.push_back(char(AttrFlags(m)));
  for (int a = 0; a < 3; ++a) PutFixed64(&s, uint64_t(m.origin[a]));
  for (int a = 0; a < 3; ++a) PutFixed64(&s, uint64_t(m.bbox_min[a]));
  for (int a = 0; a < 3; ++a) PutFixed64(&s, uint64_t(m.bbox_max[a]));
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) PutDouble(&s, m.index_to_world[c][r]);
  PutDouble(&s, m.voxel_size);
  PutFixed64(&s, m.voxel_count);
  PutFixed64(&s, m.brick_count);
  PutFixed64(&s, m.top_cells);
  PutDouble(&s, m.isovalue);
  PutDouble(&s, m.threshold);
  PutString(&s, m.build_options);
  // 1.1: the level-of-detail fields (FORMAT.md, "Level of detail").
  s.push_back(char(m.lod_level));
  PutFixed64(&s, m.lod_base_store_id);
  s.push_back(char(m.lod_base_levels));
  if (t.page_rows != 0) {  // 1.2: the brick table's pages
    PutFixed32(&s, t.page_rows);
    PutFixed32(&s, t.max_stored_size);
    PutFixed32(&s, t.max_num_cells);
    PutFixed32(&s, t.max_voxel_count);
    PutFixed64(&s, t.sum_num_cells);
    PutFixed32(&s, uint32_t(t.page_crcs.size()));
    for (uint32_t c : t.page_crcs) PutFixed32(&s, c);
  }
  return s;
}

StatusOr<StoreMeta> DecodeMeta(const uint8_t* p, size_t n, const std::string& path,
                               TableSummary* summary) {
  Reader r(p, n);
  StoreMeta m;
  m.source_file = r.String();
  m.grid_name = r.String();
  uint8_t gc = r.U8();
  m.levels = r.U8();
  m.brick_level = r.U8();
  uint8_t flags = r.U8();
  for (int a = 0; a < 3; ++a) m.origin[a] = r.I64();
  for (int a = 0; a < 3; ++a) m.bbox_min[a] = r.I64();
  for (int a = 0; a < 3; ++a) m.bbox_max[a] = r.I64();
  for (int c = 0; c < 4; ++c)
    for (int rr = 0; rr < 4; ++rr) m.index_to_world[c][rr] = r.F64();
  m.voxel_size = r.F64();
  m.voxel_count = r.U64();
  m.brick_count = r.U64();
  m.top_cells = r.U64();
  m.isovalue = r.F64();
  m.threshold = r.F64();
  m.build_options = r.String();
  if (!r.ok()) return CorruptionError("'" + path + "': metadata block too short");
  if (r.remaining() >= 10) {  // 1.1 fields (1.0: none, a base store); later ones are ignored
    m.lod_level = r.U8();
    m.lod_base_store_id = r.U64();
    m.lod_base_levels = r.U8();
  }
  TableSummary t;
  if (r.remaining() >= 28) {  // 1.2 fields
    t.page_rows = r.U32();
    t.max_stored_size = r.U32();
    t.max_num_cells = r.U32();
    t.max_voxel_count = r.U32();
    t.sum_num_cells = r.U64();
    const uint32_t count = r.U32();
    if (t.page_rows == 0 || t.page_rows > kMaxTablePageRows || count != t.pages(m.brick_count) ||
        r.remaining() < uint64_t(count) * 4)
      return CorruptionError("'" + path + "': metadata has an inconsistent brick table summary (" +
                             std::to_string(t.page_rows) + " rows per page, " +
                             std::to_string(count) + " pages for " +
                             std::to_string(m.brick_count) + " bricks)");
    t.page_crcs.resize(count);
    for (uint32_t& c : t.page_crcs) c = r.U32();
  }
  if (summary != nullptr) *summary = std::move(t);
  auto bad = [&](const std::string& what) {
    return CorruptionError("'" + path + "': metadata has " + what);
  };
  if (gc != uint8_t(GridClass::kLevelSet) && gc != uint8_t(GridClass::kFogVolume))
    return bad("unknown grid class " + std::to_string(gc));
  m.grid_class = GridClass(gc);
  if (m.levels < 1 || m.levels > kMaxLevels) return bad("levels " + std::to_string(m.levels));
  if (m.brick_level < 1 || m.brick_level > m.levels)
    return bad("brick level " + std::to_string(m.brick_level) + " outside 1.." +
               std::to_string(m.levels));
  if (flags & ~kAttrAll) return bad("unknown attribute flags " + std::to_string(flags));
  if ((m.lod_level == 0) != (m.lod_base_store_id == 0 && m.lod_base_levels == 0) ||
      (m.lod_level > 0 && m.lod_base_levels != m.levels + m.lod_level))
    return bad("inconsistent level-of-detail fields (level " + std::to_string(m.lod_level) + ")");
  m.has_normal = flags & kAttrNormal;
  m.has_density = flags & kAttrDensity;
  m.has_color = flags & kAttrColor;
  m.has_coverage = flags & kAttrCoverage;
  m.has_temperature = flags & kAttrTemperature;
  if (m.top_cells == 0 || m.top_cells >= kBrickBit)
    return bad("top cell count " + std::to_string(m.top_cells));
  if (m.brick_count >= kBrickBit) return bad("brick count " + std::to_string(m.brick_count));
  VOX_RETURN_IF_ERROR(CheckMetaFields(m, path));
  return m;
}

void EncodeBrickEntry(const BrickEntry& e, std::string* dst) {
  uint8_t b[kTableEntrySize] = {};
  EncodeFixed64(b, e.offset);
  EncodeFixed64(b + 8, e.x);
  EncodeFixed64(b + 16, e.y);
  EncodeFixed64(b + 24, e.z);
  EncodeFixed32(b + 32, e.stored_size);
  EncodeFixed32(b + 36, e.raw_size);
  EncodeFixed32(b + 40, e.num_cells);
  EncodeFixed32(b + 44, e.voxel_count);
  EncodeFixed32(b + 48, e.crc);
  b[52] = e.codec;
  dst->append(reinterpret_cast<char*>(b), sizeof(b));
}

uint32_t TablePageCrc(const uint8_t* p, size_t n) { return crc32c::Mask(crc32c::Value(p, n)); }

TableSummary SummarizeTable(const std::vector<BrickEntry>& rows, const std::string& table,
                            uint32_t page_rows) {
  TableSummary t;
  t.page_rows = page_rows;
  for (const BrickEntry& e : rows) {
    t.max_stored_size = std::max(t.max_stored_size, e.stored_size);
    t.max_num_cells = std::max(t.max_num_cells, e.num_cells);
    t.max_voxel_count = std::max(t.max_voxel_count, e.voxel_count);
    t.sum_num_cells += e.num_cells;
  }
  const size_t page_bytes = size_t(page_rows) * kTableEntrySize;
  const auto* p = reinterpret_cast<const uint8_t*>(table.data());
  for (size_t off = 0; off < table.size(); off += page_bytes)
    t.page_crcs.push_back(TablePageCrc(p + off, std::min(page_bytes, table.size() - off)));
  return t;
}

BrickEntry DecodeBrickEntry(const uint8_t* b) {
  BrickEntry e;
  e.offset = DecodeFixed64(b);
  e.x = DecodeFixed64(b + 8);
  e.y = DecodeFixed64(b + 16);
  e.z = DecodeFixed64(b + 24);
  e.stored_size = DecodeFixed32(b + 32);
  e.raw_size = DecodeFixed32(b + 36);
  e.num_cells = DecodeFixed32(b + 40);
  e.voxel_count = DecodeFixed32(b + 44);
  e.crc = DecodeFixed32(b + 48);
  e.codec = b[52];
  return e;
}

}  // namespace vox::storage_internal

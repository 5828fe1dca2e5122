#include "storage/store_info.h"

#include <sys/stat.h>

#include <algorithm>
#include <bit>
#include <cinttypes>
#include <cstdio>
#include <glm/common.hpp>
#include <limits>

#include "core/util/file.h"
#include "storage/lod.h"
#include "storage/internal/coding.h"
#include "storage/internal/format.h"
#include "storage/internal/store_impl.h"

namespace vox {

using namespace storage_internal;

StatusOr<StoreInfo> InspectStore(const std::string& dir, bool verify_bricks, size_t cache_bytes) {
  OpenOptions oo;
  oo.cache_bytes = cache_bytes;
  VOX_ASSIGN_OR_RETURN(auto store, Store::Open(dir, oo));
  StoreInfo info;
  info.dir = dir;
  info.meta = store->meta();
  std::string index_path = dir + "/" + kIndexFileName, brick_path = dir + "/" + kBrickFileName;
  VOX_ASSIGN_OR_RETURN(auto index, OpenMmapFile(index_path));
  uint8_t head[kFileHeaderSize];
  VOX_RETURN_IF_ERROR(index->Read(0, kFileHeaderSize, head));
  info.format_major = DecodeFixed16(head + 8);
  info.format_minor = DecodeFixed16(head + 10);
  info.index_file_bytes = index->size();
  struct stat st;
  if (stat(brick_path.c_str(), &st) != 0) return ErrnoError("cannot stat", brick_path, errno);
  info.brick_file_bytes = uint64_t(st.st_size);
  info.top_bytes = uint64_t(store->view().top_cells) * sizeof(CompactCell);
  info.resident_bytes = store->resident_bytes();
  VOX_ASSIGN_OR_RETURN(const std::vector<BrickEntry> table, BrickTable(*store));
  const size_t attr = AttrBytesPerVoxel(AttrFlags(info.meta));
  info.min_brick_voxels = table.empty() ? 0 : UINT64_MAX;
  for (const BrickEntry& e : table) {
    info.brick_cells += e.num_cells;
    info.stored_bytes += uint64_t(e.stored_size) + kTrailerSize;
    info.raw_bytes += e.raw_size;
    info.decoded_bytes += uint64_t(e.num_cells) * sizeof(CompactCell) + uint64_t(e.voxel_count) * attr;
    info.min_brick_voxels = std::min<uint64_t>(info.min_brick_voxels, e.voxel_count);
    info.max_brick_voxels = std::max<uint64_t>(info.max_brick_voxels, e.voxel_count);
    size_t k = size_t(std::bit_width(uint64_t(e.stored_size) + kTrailerSize)) - 1;
    if (info.stored_size_histogram.size() <= k) info.stored_size_histogram.resize(k + 1);
    ++info.stored_size_histogram[k];
  }
  if (verify_bricks) {
    for (uint32_t id = 0; id < table.size(); ++id) {
      auto b = store->FetchBrick(id);
      if (!b.ok()) return b.status();
    }
    if (HasLod(dir)) {  // every level of the pyramid, each brick checked too
      VOX_ASSIGN_OR_RETURN(auto pyramid, LodPyramid::Open(dir, *store, oo));
      for (int l = 1; l <= pyramid->max_level(); ++l) {
        Store* level = pyramid->level(l);
        // Its table read whole: every page, the block's CRC, the voxel sum.
        auto rows = BrickTable(*level);
        if (!rows.ok()) return rows.status().WithContext("level of detail " + std::to_string(l));
        const uint32_t n = uint32_t(rows->size());
        for (uint32_t id = 0; id < n; ++id) {
          auto b = level->FetchBrick(id);
          if (!b.ok()) return b.status().WithContext("level of detail " + std::to_string(l));
        }
        info.lod_levels_verified = l;
      }
    }
    info.verified = true;
  }
  return info;
}

namespace {

std::string Bytes(uint64_t b) {
  char s[64];
  if (b < 10 * 1024) snprintf(s, sizeof(s), "%" PRIu64 " B", b);
  else if (b < 10ull << 20) snprintf(s, sizeof(s), "%.1f KiB", double(b) / 1024);
  else if (b < 10ull << 30) snprintf(s, sizeof(s), "%.1f MiB", double(b) / (1 << 20));
  else snprintf(s, sizeof(s), "%.2f GiB", double(b) / (1ull << 30));
  return s;
}

std::string Vec(const glm::i64vec3& v) {
  char s[96];
  snprintf(s, sizeof(s), "(%" PRId64 ", %" PRId64 ", %" PRId64 ")", int64_t(v.x), int64_t(v.y),
           int64_t(v.z));
  return s;
}

}  // namespace

std::string FormatStoreInfo(const StoreInfo& i) {
  const StoreMeta& m = i.meta;
  std::string o;
  char line[512];
  auto add = [&](const char* fmt, auto... args) {
    snprintf(line, sizeof(line), fmt, args...);
    o += line;
  };
  const double n = m.voxel_count ? double(m.voxel_count) : 1.0;
  add("%s: vox store, format %d.%d\n", i.dir.c_str(), i.format_major, i.format_minor);
  add("  source:          %s, grid '%s' (%s)\n", m.source_file.c_str(), m.grid_name.c_str(),
      m.grid_class == GridClass::kLevelSet ? "level set" : "fog volume");
  if (m.grid_class == GridClass::kLevelSet) add("  occupied when:   active and value <= %g\n", m.isovalue);
  else add("  occupied when:   active and density > %g\n", m.threshold);
  std::string attrs;
  if (m.has_normal) attrs += " normal";
  if (m.has_density) attrs += " density";
  if (m.has_color) attrs += " colour";
  if (m.has_temperature) attrs += " temperature";
  if (m.has_coverage) attrs += " coverage";
  add("  attributes:     %s\n", attrs.empty() ? " none" : attrs.c_str());
  if (m.lod_level > 0)
    add("  level of detail: level %d of a %d-level store (store id %016llx), cells of %lld^3 voxels\n",
        m.lod_level, m.lod_base_levels, (unsigned long long)m.lod_base_store_id,
        (long long)1 << m.lod_level);
  else if (HasLod(i.dir))
    add("  level of detail: %s/lod/ (levels 1..%d; vox-render --lod)\n", i.dir.c_str(),
        LodMaxLevel(m.levels));
  add("  build options:   %s\n", m.build_options.empty() ? "-" : m.build_options.c_str());
  add("  index bbox:      %s -> %s\n", Vec(m.bbox_min).c_str(), Vec(m.bbox_max).c_str());
  glm::i64vec3 dim = m.bbox_max - m.bbox_min + glm::i64vec3(1);
  if (m.voxel_count) add("  bbox dimensions: %s\n", Vec(dim).c_str());
  add("  origin:          %s (VDB index of grid voxel 0,0,0)\n", Vec(m.origin).c_str());
  add("  voxel size:      %g\n", m.voxel_size);
  const glm::dmat4& x = m.index_to_world;
  // As vdb_print (OpenVDB's Transform::print): the matrix acting on row
  // vectors, a row a line, the translation in the last row.
  add("  index to world:\n");
  for (int r = 0; r < 4; ++r)
    add("     [%.3g, %.3g, %.3g, %.3g]\n", x[r][0], x[r][1], x[r][2], x[r][3]);
  if (m.voxel_count) {
    // The occupied voxels' extent (each voxel index +-0.5) in world space.
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
    for (int c = 0; c < 8; ++c) {
      const glm::dvec4 p((c & 1) ? m.bbox_max.x + 0.5 : m.bbox_min.x - 0.5,
                         (c & 2) ? m.bbox_max.y + 0.5 : m.bbox_min.y - 0.5,
                         (c & 4) ? m.bbox_max.z + 0.5 : m.bbox_min.z - 0.5, 1.0);
      const glm::dvec3 w(x * p);
      lo = glm::min(lo, w);
      hi = glm::max(hi, w);
    }
    add("  world bbox:      (%.9g, %.9g, %.9g) -> (%.9g, %.9g, %.9g)\n", lo.x, lo.y, lo.z, hi.x,
        hi.y, hi.z);
  }
  add("  levels:          %d (grid 2^%d per axis), brick level %d: top %d + bricks %d\n",
      m.levels, m.levels, m.brick_level, m.brick_level, m.levels - m.brick_level);
  add("  voxels:          %" PRIu64 " occupied\n", m.voxel_count);
  add("  cells:           %" PRIu64 " (top %" PRIu64 ", bricks %" PRIu64 ")\n",
      m.top_cells + i.brick_cells, m.top_cells, i.brick_cells);
  add("  bricks:          %" PRIu64 " (voxels per brick: min %" PRIu64 ", mean %.1f, max %" PRIu64 ")\n",
      m.brick_count, i.min_brick_voxels, m.brick_count ? double(m.voxel_count) / double(m.brick_count) : 0.0,
      i.max_brick_voxels);
  add("  files:           %s = %s index + %s bricks\n",
      Bytes(i.index_file_bytes + i.brick_file_bytes).c_str(), Bytes(i.index_file_bytes).c_str(),
      Bytes(i.brick_file_bytes).c_str());
  add("  resident top:    %s cells, %s with payloads and brick table\n", Bytes(i.top_bytes).c_str(),
      Bytes(i.resident_bytes).c_str());
  add("  bytes per occupied voxel: %.3f on disk (all files), %.3f brick records,\n",
      double(i.index_file_bytes + i.brick_file_bytes) / n, double(i.stored_bytes) / n);
  add("                            %.3f decompressed, %.3f in the cache (cells + attributes)\n",
      double(i.raw_bytes) / n, double(i.decoded_bytes) / n);
  if (i.stored_bytes)
    add("  compression:     %.2fx zstd (decompressed / stored), %.2fx in-cache / stored\n",
        double(i.raw_bytes) / double(i.stored_bytes), double(i.decoded_bytes) / double(i.stored_bytes));
  if (!i.stored_size_histogram.empty()) {
    o += "  brick record sizes:\n";
    uint64_t peak = *std::max_element(i.stored_size_histogram.begin(), i.stored_size_histogram.end());
    for (size_t k = 0; k < i.stored_size_histogram.size(); ++k) {
      uint64_t c = i.stored_size_histogram[k];
      if (c == 0) continue;
      std::string lo = Bytes(uint64_t(1) << k), hi = Bytes(uint64_t(1) << (k + 1));
      int bar = int((40 * c + peak - 1) / peak);
      add("    [%9s, %9s) %8" PRIu64 " %s\n", lo.c_str(), hi.c_str(), c, std::string(bar, '#').c_str());
    }
  }
  if (i.verified)
    o += "  verified:        every brick decompressed and checked" +
         (i.lod_levels_verified > 0
              ? ", pyramid levels 1.." + std::to_string(i.lod_levels_verified) + " too"
              : std::string()) +
         "\n";
  return o;
}

}  // namespace vox

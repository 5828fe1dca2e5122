#include "storage/meta_check.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace vox {
namespace {

std::string Vec(const glm::i64vec3& v) {
  char s[96];
  snprintf(s, sizeof s, "(%lld, %lld, %lld)", (long long)v.x, (long long)v.y, (long long)v.z);
  return s;
}

Status Bad(const std::string& path, const std::string& what) {
  return CorruptionError("'" + path + "': metadata has " + what);
}

// Whether the cube [lo, lo + size) lies inside m's bbox on every axis.
bool InsideBox(const glm::i64vec3& lo, int64_t size, const StoreMeta& m) {
  for (int a = 0; a < 3; ++a)
    if (lo[a] < m.bbox_min[a] || lo[a] + size - 1 > m.bbox_max[a]) return false;
  return true;
}

}  // namespace

Status CheckMetaFields(const StoreMeta& m, const std::string& path) {
  if (!(std::isfinite(m.voxel_size) && m.voxel_size > 0))
    return Bad(path, "voxel size " + std::to_string(m.voxel_size) + " (must be finite and > 0)");
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!std::isfinite(m.index_to_world[c][r]))
        return Bad(path, "a non-finite index-to-world map");
  for (int a = 0; a < 3; ++a)
    if (m.origin[a] > kMaxStoreOrigin || m.origin[a] < -kMaxStoreOrigin)
      return Bad(path, "origin " + Vec(m.origin) + " beyond +-2^52");
  if (m.lod_level != 0 || m.voxel_count == 0) return OkStatus();
  const int64_t side = int64_t(1) << m.levels;
  for (int a = 0; a < 3; ++a)
    if (m.bbox_min[a] > m.bbox_max[a] || m.bbox_min[a] < m.origin[a] ||
        m.bbox_max[a] >= m.origin[a] + side)
      return Bad(path, "bbox " + Vec(m.bbox_min) + " .. " + Vec(m.bbox_max) +
                           " outside its grid of 2^" + std::to_string(m.levels) + " voxels from " +
                           Vec(m.origin));
  return OkStatus();
}

Status CheckMetaAgainstTop(const StoreMeta& m, std::span<const CompactCell> top,
                           const std::string& path) {
  if (m.lod_level != 0 || top.empty()) return OkStatus();
  const int top_levels = m.brick_level;  // the top's levels; its last holds bricks or voxels
  struct Item {
    uint32_t cell;
    int level;
    glm::i64vec3 lo;
  };
  std::vector<Item> stack{{0, 0, m.origin}};
  glm::i64vec3 hull_lo(INT64_MAX), hull_hi(INT64_MIN);
  uint64_t cells = 0;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    if (it.cell >= top.size()) return CorruptionError("'" + path + "': top cell out of range");
    const int64_t half = int64_t(1) << (m.levels - it.level - 1);
    const uint32_t mask = ChildMask(top[it.cell]);
    if (mask == 0) continue;
    if (it.level + 1 == top_levels && InsideBox(it.lo, 2 * half, m)) {
      // Every leaf of a cell inside the bbox meets it: the leaves' hull, a
      // cell at a time (each axis's lower and upper half, from the mask).
      constexpr uint32_t kLower[3] = {0x55u, 0x33u, 0x0fu}, kUpper[3] = {0xaau, 0xccu, 0xf0u};
      cells += Popcount8(mask);
      for (int a = 0; a < 3; ++a) {
        hull_lo[a] = std::min(hull_lo[a], it.lo[a] + ((mask & kLower[a]) != 0 ? 0 : half));
        hull_hi[a] =
            std::max(hull_hi[a], it.lo[a] + ((mask & kUpper[a]) != 0 ? 2 * half : half) - 1);
      }
      continue;
    }
    for (unsigned d = 0; d < 8; ++d) {
      if (!HasChild(top[it.cell], d)) continue;
      const glm::i64vec3 lo = it.lo + glm::i64vec3(d & 1, (d >> 1) & 1, (d >> 2) & 1) * half;
      if (it.level + 1 < top_levels) {
        stack.push_back({ChildIndex(top[it.cell], d), it.level + 1, lo});
        continue;
      }
      const glm::i64vec3 hi = lo + glm::i64vec3(half - 1);
      ++cells;
      for (int a = 0; a < 3; ++a) {
        if (m.voxel_count > 0 && (hi[a] < m.bbox_min[a] || lo[a] > m.bbox_max[a]))
          return Bad(path, "bbox " + Vec(m.bbox_min) + " .. " + Vec(m.bbox_max) +
                               " missing the occupied cell " + Vec(lo) + " .. " + Vec(hi) +
                               " of the top");
        hull_lo[a] = std::min(hull_lo[a], lo[a]);
        hull_hi[a] = std::max(hull_hi[a], hi[a]);
      }
    }
  }
  if (m.voxel_count == 0) return OkStatus();
  if (cells == 0) return Bad(path, std::to_string(m.voxel_count) + " voxels but an empty top");
  for (int a = 0; a < 3; ++a)
    if (m.bbox_min[a] < hull_lo[a] || m.bbox_max[a] > hull_hi[a])
      return Bad(path, "bbox " + Vec(m.bbox_min) + " .. " + Vec(m.bbox_max) +
                           " beyond the occupied cells of the top, " + Vec(hull_lo) + " .. " +
                           Vec(hull_hi));
  return OkStatus();
}

}  // namespace vox

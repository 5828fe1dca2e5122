// Helpers shared by the storage tests: temporary directories, stores
// written from generated shapes with attributes derived from coordinates,
// and an independent voxel lookup by walking the octree. Not thread-safe.
#ifndef VOX_TESTS_STORAGE_TEST_UTIL_H_
#define VOX_TESTS_STORAGE_TEST_UTIL_H_

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <random>
#include <string>

#include "core/shapes.h"
#include "storage/internal/brick_codec.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox::storage_test {

// A fresh directory under the test temp dir, removed on destruction.
class TempDir {
 public:
  TempDir() {
    std::string base = ::testing::TempDir();
    if (base.empty()) base = "/tmp/";
    char tmpl[512];
    snprintf(tmpl, sizeof(tmpl), "%s/vox_storage_XXXXXX", base.c_str());
    char* p = mkdtemp(tmpl);
    path_ = p ? p : "";
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// Attributes that depend only on the global voxel coordinate.
inline VoxelAttributes AttrFor(uint64_t x, uint64_t y, uint64_t z, const StoreMeta& m) {
  VoxelAttributes a;
  if (m.has_normal) {
    glm::vec3 n(float(x % 7) - 3.f, float(y % 5) - 2.f, float(z % 3) - 1.f + 0.5f);
    a.normal = n / std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
  }
  if (m.has_density) a.density = float((x * 31 + y * 17 + z * 7) % 1000) / 997.f + 0.001f;
  if (m.has_color) a.color = glm::vec3(float(x % 16) / 15.f, float(y % 8) / 7.f, float(z % 4) * 0.75f);
  return a;
}

inline StoreMeta MetaFor(int levels, int brick_level, GridClass gc, bool color) {
  StoreMeta m;
  m.source_file = "generated";
  m.grid_name = "shape";
  m.grid_class = gc;
  m.levels = levels;
  m.brick_level = brick_level;
  m.origin = glm::i64vec3(-5, 7, -1000);
  m.index_to_world = glm::dmat4(0.5);
  m.index_to_world[3] = glm::dvec4(1, 2, 3, 1);
  m.voxel_size = 0.5;
  m.has_normal = gc == GridClass::kLevelSet;
  m.has_density = gc == GridClass::kFogVolume;
  m.has_color = color;
  m.isovalue = 0.25;
  m.threshold = 0.01;
  m.build_options = "--test";
  return m;
}

// The decoded contents of a brick as bytes: cells, attribute values, voxel count.
inline std::string BrickBytes(const BrickView& v) {
  const auto* b = static_cast<const storage_internal::DecodedBrick*>(v.data);
  std::string out(reinterpret_cast<const char*>(v.cells), v.num_cells * sizeof(CompactCell));
  out.append(reinterpret_cast<const char*>(b->attr_values.data()), b->attr_values.size());
  out.append(reinterpret_cast<const char*>(&b->voxel_count), sizeof(b->voxel_count));
  if (b->common) {  // (the common density and its bits)
    out.append(reinterpret_cast<const char*>(&b->common_density), sizeof(b->common_density));
    out.append(reinterpret_cast<const char*>(b->common_words.data()),
               b->common_words.size() * sizeof(storage_internal::DecodedBrick::CommonWord));
  }
  return out;
}

// Interleaves the bits of a brick coordinate (z highest): brick id order.
inline uint64_t MortonKey(const glm::u64vec3& c) {
  uint64_t k = 0;
  for (int b = 0; b < 21; ++b)
    k |= ((c.x >> b) & 1) << (3 * b) | ((c.y >> b) & 1) << (3 * b + 1) |
         ((c.z >> b) & 1) << (3 * b + 2);
  return k;
}

// Writes `voxels` (global grid coordinates) as a store: bricks in a shuffled
// order (or in Morton order, as vox-ingest and vox-gen write them, when
// `shuffle_bricks` is false), voxels shuffled within each brick (or kept in
// the given order).
inline Status WriteVoxels(const std::string& dir, const std::vector<LeafPoint>& voxels,
                          const StoreMeta& meta, WriteOptions opts = {}, uint64_t seed = 1,
                          bool shuffle_voxels = true, bool shuffle_bricks = true) {
  const int sub = meta.levels - meta.brick_level;
  std::map<std::tuple<uint64_t, uint64_t, uint64_t>, std::vector<BrickVoxel>> bricks;
  const uint64_t lm = (uint64_t(1) << sub) - 1;
  for (const LeafPoint& p : voxels) {
    BrickVoxel v;
    v.x = uint32_t(p.x & lm);
    v.y = uint32_t(p.y & lm);
    v.z = uint32_t(p.z & lm);
    v.attr = AttrFor(p.x, p.y, p.z, meta);
    bricks[{p.x >> sub, p.y >> sub, p.z >> sub}].push_back(v);
  }
  std::vector<std::pair<glm::u64vec3, std::vector<BrickVoxel>>> list;
  for (auto& [k, v] : bricks)
    list.push_back({glm::u64vec3(std::get<0>(k), std::get<1>(k), std::get<2>(k)), std::move(v)});
  std::mt19937_64 rng(seed);
  if (shuffle_bricks)
    std::shuffle(list.begin(), list.end(), rng);
  else
    std::sort(list.begin(), list.end(), [](const auto& a, const auto& b) {
      return MortonKey(a.first) < MortonKey(b.first);
    });
  auto w = StoreWriter::Create(dir, meta, opts);
  if (!w.ok()) return w.status();
  for (auto& [c, v] : list) {
    if (shuffle_voxels) std::shuffle(v.begin(), v.end(), rng);
    Status s = (*w)->AddBrick(c, std::move(v));
    if (!s.ok()) return s;
  }
  return (*w)->Finish();
}

struct Located {
  uint32_t brick = kNoBrick;
  uint32_t payload = 0;
};

// Finds voxel (x,y,z) by descending the store's octree cell by cell.
inline StatusOr<std::optional<Located>> Locate(Store& store, uint64_t x, uint64_t y, uint64_t z) {
  OctreeView v = store.view();
  const CompactCell* pool = v.top;
  CompactCell cell = v.top[0];
  BrickView pin;
  uint32_t brick = kNoBrick;
  for (int level = 0; level < v.levels; ++level) {
    const int bit = v.levels - 1 - level;
    unsigned d = unsigned((x >> bit) & 1) | unsigned(((y >> bit) & 1) << 1) |
                 unsigned(((z >> bit) & 1) << 2);
    ChildRef r = ChildOf(cell, d, level, v);
    if (r.kind == ChildRef::kEmpty) return std::optional<Located>();
    if (r.kind == ChildRef::kPayload) return std::optional<Located>(Located{brick, r.index});
    if (r.kind == ChildRef::kBrick) {
      brick = r.index;
      auto b = store.FetchBrick(brick);
      if (!b.ok()) return b.status();
      pin = *b;
      pool = pin.cells;
      cell = pool[0];
    } else {
      cell = pool[r.index];
    }
  }
  return std::optional<Located>();
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}
inline void WriteFile(const std::string& path, const std::string& data) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(data.data(), std::streamsize(data.size()));
}

}  // namespace vox::storage_test

#endif  // VOX_TESTS_STORAGE_TEST_UTIL_H_

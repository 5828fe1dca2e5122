// testutil::ExpectSameStore: two stores are the same store (FORMAT.md's
// metadata but for the store id, source and build options; every voxel in
// the same brick and payload with the same attributes), and with
// ExpectSameStoreAndPyramid their level-of-detail pyramids too. For the
// ingest tests that make one store two ways.
#ifndef VOX_TESTS_INGEST_SAME_STORE_H_
#define VOX_TESTS_INGEST_SAME_STORE_H_

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "storage/lod.h"
#include "storage/store.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox::testutil {

inline void ExpectSameMeta(const StoreMeta& a, const StoreMeta& b) {
  EXPECT_EQ(a.grid_name, b.grid_name);
  EXPECT_EQ(a.grid_class, b.grid_class);
  EXPECT_EQ(a.levels, b.levels);
  EXPECT_EQ(a.brick_level, b.brick_level);
  EXPECT_EQ(a.origin, b.origin);
  EXPECT_EQ(a.bbox_min, b.bbox_min);
  EXPECT_EQ(a.bbox_max, b.bbox_max);
  EXPECT_EQ(a.index_to_world, b.index_to_world);
  EXPECT_EQ(a.voxel_size, b.voxel_size);
  EXPECT_EQ(a.voxel_count, b.voxel_count);
  EXPECT_EQ(a.brick_count, b.brick_count);
  EXPECT_EQ(a.top_cells, b.top_cells);
  EXPECT_EQ(a.has_normal, b.has_normal);
  EXPECT_EQ(a.has_density, b.has_density);
  EXPECT_EQ(a.has_color, b.has_color);
  EXPECT_EQ(a.has_coverage, b.has_coverage);
  EXPECT_EQ(a.has_temperature, b.has_temperature);
  EXPECT_EQ(a.isovalue, b.isovalue);
  EXPECT_EQ(a.threshold, b.threshold);
  EXPECT_EQ(a.lod_level, b.lod_level);
  EXPECT_EQ(a.lod_base_levels, b.lod_base_levels);
}

// The same store: metadata, and every voxel in the same brick and payload
// with the same attributes. Returns the voxel count.
inline size_t ExpectSameStore(const std::string& a_dir, const std::string& b_dir) {
  auto a = Store::Open(a_dir, OpenOptions{});
  auto b = Store::Open(b_dir, OpenOptions{});
  EXPECT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_TRUE(b.ok()) << b.status().ToString();
  if (!a.ok() || !b.ok()) return 0;
  ExpectSameMeta((*a)->meta(), (*b)->meta());
  auto va = testutil::ReadAll(**a);
  auto vb = testutil::ReadAll(**b);
  EXPECT_TRUE(va.ok() && vb.ok());
  if (!va.ok() || !vb.ok()) return 0;
  EXPECT_EQ(va->size(), vb->size());
  if (va->size() != vb->size()) return 0;
  for (auto ia = va->begin(), ib = vb->begin(); ia != va->end(); ++ia, ++ib) {
    EXPECT_EQ(ia->first, ib->first);
    EXPECT_EQ(ia->second.brick, ib->second.brick);
    EXPECT_EQ(ia->second.payload, ib->second.payload);
    auto aa = (*a)->Attributes(ia->second.brick, ia->second.payload);
    auto ab = (*b)->Attributes(ib->second.brick, ib->second.payload);
    EXPECT_TRUE(aa.ok() && ab.ok());
    if (!aa.ok() || !ab.ok() || ia->first != ib->first) return 0;
    EXPECT_EQ(aa->density, ab->density);
    EXPECT_EQ(aa->coverage, ab->coverage);
  }
  return va->size();
}

// The same store and the same pyramid, level by level. Returns the base's voxel count.
inline size_t ExpectSameStoreAndPyramid(const std::string& a_dir, const std::string& b_dir) {
  const size_t n = ExpectSameStore(a_dir, b_dir);
  EXPECT_EQ(HasLod(a_dir), HasLod(b_dir));
  int levels = 0;
  for (int l = 1; std::filesystem::exists(a_dir + "/lod/" + std::to_string(l)); ++l, ++levels) {
    SCOPED_TRACE("level " + std::to_string(l));
    ExpectSameStore(a_dir + "/lod/" + std::to_string(l), b_dir + "/lod/" + std::to_string(l));
  }
  EXPECT_FALSE(std::filesystem::exists(b_dir + "/lod/" + std::to_string(levels + 1)));
  return n;
}

}  // namespace vox::testutil

#endif  // VOX_TESTS_INGEST_SAME_STORE_H_

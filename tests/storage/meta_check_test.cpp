// Store metadata edited with a valid CRC is refused at open (voxel
// size 0, -1 or NaN, origins near INT64_MAX, a bbox shrunk or grown past the
// occupied bricks of the resident top), and `InspectStore(..., verify)`
// (vox-info --verify) checks every pyramid level: a byte flipped in
// lod/1/bricks.vxb or a level removed fails, where it was reported verified.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <string>

#include "storage/internal/format.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_info.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using namespace storage_internal;
using storage_test::ReadFile;
using storage_test::TempDir;
using storage_test::WriteFile;

// Rewrites the metadata block of the store at `dir` through `edit`, with
// valid checksums, keeping every other block.
void EditMeta(const std::string& dir, const std::function<void(StoreMeta*)>& edit) {
  const std::string index = ReadFile(dir + "/index.vxi");
  auto footer = DecodeFooter(
      reinterpret_cast<const uint8_t*>(index.data()) + index.size() - kFooterSize, "x");
  ASSERT_TRUE(footer.ok());
  Footer f = *footer;
  auto block = [&](const BlockHandle& h) { return index.substr(h.offset, h.size); };
  StoreMeta m;
  {
    // DecodeMeta checks the fields; read them back from a copy that passes.
    auto decoded = DecodeMeta(reinterpret_cast<const uint8_t*>(index.data()) + f.meta.offset,
                              f.meta.size, "x");
    ASSERT_TRUE(decoded.ok());
    m = *decoded;
  }
  edit(&m);
  const std::string top = block(f.top), attr = block(f.top_attr), table = block(f.table);
  std::string out = index.substr(0, kFileHeaderSize);
  auto put = [&](const std::string& b, BlockHandle* h) {
    h->offset = out.size();
    h->size = b.size();
    out += b + BlockTrailer(b.data(), b.size(), kCodecRaw);
  };
  put(EncodeMeta(m), &f.meta);
  put(top, &f.top);
  put(attr, &f.top_attr);
  put(table, &f.table);
  out += EncodeFooter(f);
  WriteFile(dir + "/index.vxi", out);
}

class MetaCheck : public ::testing::Test {
 protected:
  void SetUp() override {
    meta_ = storage_test::MetaFor(7, 4, GridClass::kLevelSet, false);  // bricks of 8^3
    // Voxels in two bricks far apart: the bbox spans both.
    ASSERT_TRUE(storage_test::WriteVoxels(good_, {LeafPoint{1, 2, 3}, LeafPoint{100, 90, 80}},
                                          meta_)
                    .ok());
  }
  // Opens a copy of the good store with `edit` applied to its metadata.
  Status OpenEdited(const std::function<void(StoreMeta*)>& edit) {
    const std::string dir = tmp_ / ("e" + std::to_string(n_++));
    std::filesystem::copy(good_, dir, std::filesystem::copy_options::recursive);
    EditMeta(dir, edit);
    return Store::Open(dir, {}).status();
  }
  TempDir tmp_;
  std::string good_ = tmp_ / "good";
  StoreMeta meta_;
  int n_ = 0;
};

TEST_F(MetaCheck, TheGoodStoreAndAnUneditedRewriteOpen) {
  ASSERT_TRUE(Store::Open(good_, {}).ok());
  EXPECT_TRUE(OpenEdited([](StoreMeta*) {}).ok());
}

TEST_F(MetaCheck, VoxelSizeMustBeFiniteAndPositive) {
  for (double size : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    const Status s = OpenEdited([size](StoreMeta* m) { m->voxel_size = size; });
    EXPECT_EQ(s.code(), StatusCode::kCorruption) << size << ": " << s.ToString();
    EXPECT_NE(s.message().find("voxel size"), std::string::npos) << s.ToString();
  }
}

TEST_F(MetaCheck, OriginsThatCouldOverflowAreRefused) {
  const Status s = OpenEdited([](StoreMeta* m) {
    m->origin.x = INT64_MAX;
    m->bbox_min.x = INT64_MAX - 200;
    m->bbox_max.x = INT64_MAX - 10;
  });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_NE(s.message().find("origin"), std::string::npos) << s.ToString();
}

TEST_F(MetaCheck, TheBboxMustAgreeWithTheOccupiedBricks) {
  // Shrunk to the first brick: the far brick lies outside it.
  Status s = OpenEdited([](StoreMeta* m) { m->bbox_max = m->bbox_min; });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_NE(s.message().find("bbox"), std::string::npos) << s.ToString();
  // Grown past the bricks (still inside the grid).
  s = OpenEdited([](StoreMeta* m) { m->bbox_max = m->origin + glm::i64vec3(127); });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  // Grown to the far brick's parent cell (grid 96..111, 80..95, 80..95), which
  // the brick (96..103, 88..95, 80..87) fills only in part: the check takes
  // such a cell's leaves from its child mask.
  s = OpenEdited([](StoreMeta* m) { m->bbox_max = m->origin + glm::i64vec3(111, 95, 95); });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_NE(s.message().find("beyond the occupied cells"), std::string::npos) << s.ToString();
  // One voxel past the brick on one axis.
  for (int a = 0; a < 3; ++a) {
    s = OpenEdited([a](StoreMeta* m) {
      m->bbox_max = m->origin + glm::i64vec3(103, 95, 87);
      m->bbox_max[a] += 1;
    });
    EXPECT_EQ(s.code(), StatusCode::kCorruption) << a << ": " << s.ToString();
  }
  EXPECT_TRUE(
      OpenEdited([](StoreMeta* m) { m->bbox_max = m->origin + glm::i64vec3(103, 95, 87); }).ok());
  // Huge: past the grid.
  s = OpenEdited([](StoreMeta* m) { m->bbox_max = glm::i64vec3(INT64_MAX / 2); });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  // Inverted.
  s = OpenEdited([](StoreMeta* m) { std::swap(m->bbox_min, m->bbox_max); });
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
}

TEST_F(MetaCheck, VerifyChecksEveryPyramidLevel) {
  ASSERT_TRUE(BuildLod(good_, LodBuildOptions{}).ok());
  auto info = InspectStore(good_, /*verify_bricks=*/true);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_TRUE(info->verified);
  const int levels = info->lod_levels_verified;
  EXPECT_GE(levels, 1);
  EXPECT_NE(FormatStoreInfo(*info).find("pyramid levels 1.."), std::string::npos);
  // A byte flipped in a level-1 brick record.
  const std::string level1 = good_ + "/lod/1/bricks.vxb";
  std::string bytes = ReadFile(level1);
  ASSERT_GT(bytes.size(), kFileHeaderSize + 4);
  const std::string saved = bytes;
  bytes[kFileHeaderSize + 2] ^= 0x40;
  WriteFile(level1, bytes);
  info = InspectStore(good_, true);
  EXPECT_FALSE(info.ok()) << "a flipped byte in lod/1 was verified";
  EXPECT_NE(info.status().ToString().find("lod/1"), std::string::npos) << info.status().ToString();
  EXPECT_TRUE(InspectStore(good_, false).ok()) << "without --verify the bricks are not read";
  WriteFile(level1, saved);
  // A level removed: --verify and --lod both fail, naming it.
  const int top = levels;
  std::filesystem::remove_all(good_ + "/lod/" + std::to_string(top));
  info = InspectStore(good_, true);
  EXPECT_FALSE(info.ok());
  auto base = Store::Open(good_, {});
  ASSERT_TRUE(base.ok());
  auto pyramid = LodPyramid::Open(good_, **base, {});
  EXPECT_FALSE(pyramid.ok());
  EXPECT_NE(pyramid.status().ToString().find("lod/" + std::to_string(top)), std::string::npos)
      << pyramid.status().ToString();
}

}  // namespace
}  // namespace vox

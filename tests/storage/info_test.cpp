// InspectStore's statistics against independent counts (MemoryOctree over
// the same voxels, the file system), and vox-info's output and exit codes.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <cstdio>

#include "storage/store_info.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

uint64_t FileSize(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0 ? uint64_t(st.st_size) : 0;
}

// Runs a command; returns its exit code and stdout+stderr.
std::pair<int, std::string> RunCommand(const std::string& cmd) {
  std::string out;
  FILE* f = popen((cmd + " 2>&1").c_str(), "r");
  if (f == nullptr) return {-1, ""};
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), f)) > 0) out.append(buf, n);
  int st = pclose(f);
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out};
}

class Info : public ::testing::Test {
 protected:
  void SetUp() override {
    auto vol = GenerateShape("torus:64");
    ASSERT_TRUE(vol.ok());
    voxels_ = vol->voxels;
    meta_ = storage_test::MetaFor(vol->levels, 3, GridClass::kFogVolume, true);
    dir_ = tmp_ / "store";
    ASSERT_TRUE(storage_test::WriteVoxels(dir_, voxels_, meta_).ok());
  }
  storage_test::TempDir tmp_;
  std::string dir_;
  std::vector<LeafPoint> voxels_;
  StoreMeta meta_;
};

TEST_F(Info, StatisticsMatchIndependentCounts) {
  auto info = InspectStore(dir_, /*verify_bricks=*/true);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  auto mem = MemoryOctree::Build(voxels_, meta_.levels, meta_.brick_level);
  ASSERT_TRUE(mem.ok());
  uint64_t cells = 0;
  for (uint32_t i = 0; i < (*mem)->num_bricks(); ++i) cells += (*mem)->FetchBrick(i)->num_cells;
  EXPECT_EQ(info->meta.voxel_count, voxels_.size());
  EXPECT_EQ(info->meta.brick_count, (*mem)->num_bricks());
  EXPECT_EQ(info->brick_cells, cells);
  EXPECT_EQ(info->meta.top_cells, (*mem)->view().top_cells);
  EXPECT_EQ(info->top_bytes, 4u * (*mem)->view().top_cells);
  EXPECT_EQ(info->index_file_bytes, FileSize(dir_ + "/index.vxi"));
  EXPECT_EQ(info->brick_file_bytes, FileSize(dir_ + "/bricks.vxb"));
  // Density (4) + colour (6) bytes per voxel, and the cells at 4 bytes.
  EXPECT_EQ(info->decoded_bytes, 4 * cells + 10 * voxels_.size());
  EXPECT_EQ(info->raw_bytes, 16 * info->meta.brick_count + cells + 10 * voxels_.size());
  EXPECT_LT(info->stored_bytes, info->brick_file_bytes);
  uint64_t hist = 0;
  for (uint64_t h : info->stored_size_histogram) hist += h;
  EXPECT_EQ(hist, info->meta.brick_count);
  EXPECT_TRUE(info->verified);
  EXPECT_EQ(info->format_major, 1);
  std::string text = FormatStoreInfo(*info);
  EXPECT_NE(text.find("voxels:          " + std::to_string(voxels_.size()) + " occupied"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("fog volume"), std::string::npos);
  EXPECT_NE(text.find("bytes per occupied voxel"), std::string::npos);
  EXPECT_NE(text.find("brick record sizes"), std::string::npos);
}

TEST_F(Info, VerifyFindsACorruptBrick) {
  std::string b = storage_test::ReadFile(dir_ + "/bricks.vxb");
  b[b.size() - 40] ^= 0x20;
  storage_test::WriteFile(dir_ + "/bricks.vxb", b);
  EXPECT_TRUE(InspectStore(dir_, false).ok());  // the index alone is fine
  auto v = InspectStore(dir_, true);
  EXPECT_EQ(v.status().code(), StatusCode::kCorruption);
  EXPECT_NE(v.status().message().find("brick "), std::string::npos) << v.status().ToString();
}

TEST_F(Info, ToolOutputAndExitCodes) {
  const std::string bin = VOX_INFO_BIN;
  auto [code, out] = RunCommand(bin + " " + dir_ + " --verify");
  EXPECT_EQ(code, 0) << out;
  EXPECT_NE(out.find("verified"), std::string::npos) << out;
  EXPECT_NE(out.find(std::to_string(voxels_.size())), std::string::npos) << out;
  auto [c2, o2] = RunCommand(bin + " " + tmp_ / "missing");
  EXPECT_EQ(c2, 1);
  EXPECT_NE(o2.find("vox-info: NotFound"), std::string::npos) << o2;
  storage_test::WriteFile(dir_ + "/index.vxi", "garbage");
  auto [c3, o3] = RunCommand(bin + " " + dir_);
  EXPECT_EQ(c3, 1);
  EXPECT_NE(o3.find("index.vxi"), std::string::npos) << o3;
  EXPECT_EQ(RunCommand(bin).first, 2);
  EXPECT_EQ(RunCommand(bin + " --bogus x").first, 2);
}

}  // namespace
}  // namespace vox

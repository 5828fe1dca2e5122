// --force replaces only a complete vox store (exactly index.vxi and
// bricks.vxb with valid headers and one store_id) or an empty directory; and
// StoreWriter removes the temporary directories `.NAME.tmp-PID-XXXXXXXX` of
// writers whose process is gone, never those of a live one.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>

#include "tests/storage/test_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using storage_test::TempDir;

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

class Force : public ::testing::Test {
 protected:
  void SetUp() override {
    auto a = GenerateShape("sphere:32");
    ASSERT_TRUE(a.ok());
    a_ = a->voxels;
    meta_ = storage_test::MetaFor(a->levels, 3, GridClass::kLevelSet, false);
    wo_.force = true;
  }
  // Expects --force onto `dir` to be refused, naming why, with `keep` intact.
  void ExpectRefused(const std::string& dir, const std::string& why, const std::string& keep) {
    const std::string before = storage_test::ReadFile(keep);
    Status s = storage_test::WriteVoxels(dir, a_, meta_, wo_);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
    EXPECT_TRUE(Contains(s.message(), "not a vox store") && Contains(s.message(), why))
        << s.ToString();
    EXPECT_EQ(storage_test::ReadFile(keep), before);
  }
  TempDir tmp_;
  std::vector<LeafPoint> a_;
  StoreMeta meta_;
  WriteOptions wo_;
};

TEST_F(Force, NotesBesideAnEmptyBrickFileAreKept) {
  fs::create_directory(tmp_ / "d");
  storage_test::WriteFile(tmp_ / "d/notes.txt", "my notes");
  storage_test::WriteFile(tmp_ / "d/bricks.vxb", "");
  ExpectRefused(tmp_ / "d", "notes.txt", tmp_ / "d/notes.txt");
  EXPECT_TRUE(fs::exists(tmp_ / "d/bricks.vxb"));
}

TEST_F(Force, AStoreWithAnotherFileIsRefused) {
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s", a_, meta_).ok());
  storage_test::WriteFile(tmp_ / "s/README", "about this store");
  ExpectRefused(tmp_ / "s", "README", tmp_ / "s/README");
  EXPECT_TRUE(Store::Open(tmp_ / "s", {}).ok());
}

TEST_F(Force, FilesThatAreNotAStoreAreRefused) {
  // Only one of the two files.
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s", a_, meta_).ok());
  fs::remove(tmp_ / "s/bricks.vxb");
  ExpectRefused(tmp_ / "s", "bricks.vxb", tmp_ / "s/index.vxi");
  // Files with the right names but other content.
  fs::create_directory(tmp_ / "t");
  storage_test::WriteFile(tmp_ / "t/index.vxi", std::string(200, 'x'));
  storage_test::WriteFile(tmp_ / "t/bricks.vxb", std::string(200, 'y'));
  ExpectRefused(tmp_ / "t", "index.vxi", tmp_ / "t/index.vxi");
  // The index of one store beside the bricks of another.
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "u", a_, meta_).ok());
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "v", a_, meta_).ok());
  fs::copy_file(tmp_ / "v/bricks.vxb", tmp_ / "u/bricks.vxb", fs::copy_options::overwrite_existing);
  ExpectRefused(tmp_ / "u", "different stores", tmp_ / "u/index.vxi");
}

TEST_F(Force, AStoreOrAnEmptyDirectoryIsReplaced) {
  fs::create_directory(tmp_ / "empty");
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "empty", a_, meta_, wo_).ok());
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "empty", a_, meta_, wo_).ok());
  auto st = Store::Open(tmp_ / "empty", {});
  ASSERT_TRUE(st.ok()) << st.status().ToString();
  EXPECT_EQ((*st)->meta().voxel_count, a_.size());
}

pid_t DeadPid() {
  pid_t pid = fork();
  if (pid == 0) _exit(0);
  int status = 0;
  waitpid(pid, &status, 0);
  return pid;
}

TEST_F(Force, StaleTemporariesOfDeadWritersAreRemoved) {
  const std::string dead = std::to_string(DeadPid());
  const std::string live = std::to_string(getppid());
  const std::vector<std::string> stale = {".s.tmp-" + dead + "-0123abcd",
                                          ".s.tmp-" + dead + "-89abcdef.old"};
  const std::vector<std::string> kept = {
      ".s.tmp-" + live + "-0123abcd",  // a live writer's
      ".t.tmp-" + dead + "-0123abcd",  // another store's
      ".s.tmp-" + dead + "-notahex1",  // not the writer's pattern
      ".s.tmp-" + dead + "-0123abcd-x"};
  for (const auto& d : stale) {
    fs::create_directory(tmp_ / d);
    storage_test::WriteFile(tmp_ / (d + "/bricks.vxb"), "partial");
  }
  for (const auto& d : kept) fs::create_directory(tmp_ / d);
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s", a_, meta_).ok());
  for (const auto& d : stale) EXPECT_FALSE(fs::exists(tmp_ / d)) << d;
  for (const auto& d : kept) EXPECT_TRUE(fs::exists(tmp_ / d)) << d;
  EXPECT_TRUE(Store::Open(tmp_ / "s", {}).ok());
}

}  // namespace
}  // namespace vox

// The atomic writer: an existing target is refused without force, replaced
// with it; abandoned or killed writers leave nothing that opens; unwritable
// targets and a full disk give clear errors naming the file.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
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

std::vector<std::string> Entries(const std::string& dir) {
  std::vector<std::string> v;
  for (auto& e : fs::directory_iterator(dir)) v.push_back(e.path().filename().string());
  std::sort(v.begin(), v.end());
  return v;
}

class Writer : public ::testing::Test {
 protected:
  void SetUp() override {
    auto a = GenerateShape("sphere:32");
    auto b = GenerateShape("torus:32");
    ASSERT_TRUE(a.ok() && b.ok());
    a_ = a->voxels;
    b_ = b->voxels;
    meta_ = storage_test::MetaFor(a->levels, 3, GridClass::kLevelSet, false);
  }
  TempDir tmp_;
  std::vector<LeafPoint> a_, b_;
  StoreMeta meta_;
};

TEST_F(Writer, ExistingTargetRefusedWithoutForce) {
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s", a_, meta_).ok());
  Status s = storage_test::WriteVoxels(tmp_ / "s", b_, meta_);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(s.message(), "already exists") && Contains(s.message(), "--force"))
      << s.ToString();
  auto st = Store::Open(tmp_ / "s", {});
  ASSERT_TRUE(st.ok());
  EXPECT_EQ((*st)->meta().voxel_count, a_.size());
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"s"});
}

TEST_F(Writer, ForceReplacesAStore) {
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s", a_, meta_).ok());
  WriteOptions wo;
  wo.force = true;
  ASSERT_TRUE(storage_test::WriteVoxels(tmp_ / "s/", b_, meta_, wo).ok());
  auto st = Store::Open(tmp_ / "s", {});
  ASSERT_TRUE(st.ok());
  EXPECT_EQ((*st)->meta().voxel_count, b_.size());
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"s"});  // old store and temp gone
}

TEST_F(Writer, ForceNeverReplacesOtherData) {
  fs::create_directory(tmp_ / "data");
  storage_test::WriteFile(tmp_ / "data/precious.txt", "keep me");
  WriteOptions wo;
  wo.force = true;
  Status s = storage_test::WriteVoxels(tmp_ / "data", a_, meta_, wo);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(s.message(), "not a vox store")) << s.ToString();
  EXPECT_EQ(storage_test::ReadFile(tmp_ / "data/precious.txt"), "keep me");
  storage_test::WriteFile(tmp_ / "plain", "x");
  EXPECT_FALSE(storage_test::WriteVoxels(tmp_ / "plain", a_, meta_, wo).ok());
  EXPECT_EQ(storage_test::ReadFile(tmp_ / "plain"), "x");
}

TEST_F(Writer, AbandonedWriterLeavesNothing) {
  {
    auto w = StoreWriter::Create(tmp_ / "s", meta_, {});
    ASSERT_TRUE(w.ok());
    BrickVoxel v;
    ASSERT_TRUE((*w)->AddBrick({1, 2, 3}, {v}).ok());
    EXPECT_EQ(Entries(tmp_.path()).size(), 1u);  // the temporary directory
    EXPECT_TRUE(Entries(tmp_.path())[0].rfind(".s.tmp-", 0) == 0);
  }
  EXPECT_TRUE(Entries(tmp_.path()).empty());
  EXPECT_EQ(Store::Open(tmp_ / "s", {}).status().code(), StatusCode::kNotFound);
}

TEST_F(Writer, KilledWriterLeavesOnlyATempDirThatNeverOpens) {
  pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    auto w = StoreWriter::Create(tmp_ / "s", meta_, {});
    if (!w.ok()) _exit(2);
    BrickVoxel v;
    for (uint64_t i = 0; i < 5; ++i)
      if (!(*w)->AddBrick({i, 0, 0}, {v}).ok()) _exit(3);
    raise(SIGKILL);  // no destructor, no Finish
    _exit(4);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << status;
  auto entries = Entries(tmp_.path());
  ASSERT_EQ(entries.size(), 1u);
  EXPECT_TRUE(entries[0].rfind(".s.tmp-", 0) == 0) << entries[0];
  EXPECT_EQ(Store::Open(tmp_ / "s", {}).status().code(), StatusCode::kNotFound);
  auto t = Store::Open(tmp_ / entries[0], {});
  EXPECT_FALSE(t.ok());
  EXPECT_TRUE(Contains(t.status().message(), "index.vxi")) << t.status().ToString();
}

TEST_F(Writer, UnwritableTargets) {
  auto s1 = StoreWriter::Create(tmp_ / "missing/dir/s", meta_, {});
  EXPECT_EQ(s1.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s1.status().message(), "missing/dir")) << s1.status().ToString();
  storage_test::WriteFile(tmp_ / "file", "x");
  auto s2 = StoreWriter::Create(tmp_ / "file/s", meta_, {});
  EXPECT_FALSE(s2.ok());
  EXPECT_TRUE(Contains(s2.status().message(), "file")) << s2.status().ToString();
  // The kernel refuses new entries in /proc even for root.
  auto s3 = StoreWriter::Create("/proc/self/vox_store", meta_, {});
  EXPECT_FALSE(s3.ok());
  EXPECT_TRUE(Contains(s3.status().message(), "/proc/self/")) << s3.status().ToString();
  WriteOptions level99;
  level99.zstd_level = 99;
  EXPECT_EQ(StoreWriter::Create(tmp_ / "s", meta_, level99).status().code(),
            StatusCode::kInvalidArgument);
  StoreMeta bad = meta_;
  bad.brick_level = bad.levels + 1;
  EXPECT_EQ(StoreWriter::Create(tmp_ / "s", bad, {}).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_F(Writer, DiskFullNamesTheFileAndCleansUp) {
  // RLIMIT_FSIZE makes write() fail with EFBIG, like a full disk, for root too.
  auto big = GenerateShape("sphere:128");
  ASSERT_TRUE(big.ok());
  StoreMeta m = storage_test::MetaFor(big->levels, 4, GridClass::kLevelSet, true);
  std::string dir = tmp_ / "s";
  auto child = [&] {
    signal(SIGXFSZ, SIG_IGN);
    struct rlimit rl;
    rl.rlim_cur = rl.rlim_max = 64 << 10;
    setrlimit(RLIMIT_FSIZE, &rl);
    Status s = storage_test::WriteVoxels(dir, big->voxels, m);
    bool clean = Entries(tmp_.path()).empty();
    fprintf(stderr, "%s clean=%d\n", s.ToString().c_str(), int(clean));
    _exit(s.code() == StatusCode::kResourceExhausted && clean ? 0 : 1);
  };
  EXPECT_EXIT(child(), ::testing::ExitedWithCode(0), "ResourceExhausted: writing store '.*': cannot write '.*bricks.vxb'.* clean=1");
}

}  // namespace
}  // namespace vox

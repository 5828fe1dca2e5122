// Publication never removes what it did not check. Each race between a
// writer's check of its target and its publish is made deterministic: the
// store writer's before_publish hook (or, for vox-gen, its test gate FIFO)
// changes the target in between, and AtomicFile's target is changed between
// Create and Commit. Every case runs with renameat2's flags and with the
// fallbacks used where the file system lacks them.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include "core/util/atomic_file.h"
#include "core/util/file.h"
#include "tests/common/run_command.h"
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

class PublishRace : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    SetRenameFlagsUnsupportedForTesting(GetParam());
    auto a = GenerateShape("sphere:32");
    auto b = GenerateShape("torus:32");
    ASSERT_TRUE(a.ok() && b.ok());
    a_ = a->voxels;
    b_ = b->voxels;
    meta_ = storage_test::MetaFor(a->levels, 3, GridClass::kLevelSet, false);
  }
  void TearDown() override { SetRenameFlagsUnsupportedForTesting(false); }
  uint64_t VoxelsAt(const std::string& dir) {
    auto st = Store::Open(dir, {});
    return st.ok() ? (*st)->meta().voxel_count : 0;
  }
  // Writes b_ at `dir` with `wo`, running `between` after the writer's check
  // and before its publish.
  Status WriteRacing(const std::string& dir, WriteOptions wo, std::function<void()> between) {
    wo.before_publish = [between](const std::string&) {
      between();
      return OkStatus();
    };
    return storage_test::WriteVoxels(dir, b_, meta_, wo);
  }
  TempDir tmp_;
  std::vector<LeafPoint> a_, b_;
  StoreMeta meta_;
};

// The loss: a directory made at the target during the ingest.
TEST_P(PublishRace, DirectoryMadeAtNewTargetIsKept) {
  for (bool force : {false, true}) {
    const std::string victim = tmp_ / (force ? "victim_f" : "victim");
    WriteOptions wo;
    wo.force = force;
    Status s = WriteRacing(victim, wo, [&] {
      fs::create_directory(victim);
      storage_test::WriteFile(victim + "/important.txt", "precious");
    });
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
    EXPECT_TRUE(Contains(s.message(), "already exists")) << s.ToString();
    EXPECT_EQ(Contains(s.message(), "--force"), !force) << s.ToString();
    EXPECT_EQ(storage_test::ReadFile(victim + "/important.txt"), "precious");
    EXPECT_EQ(Entries(victim), std::vector<std::string>{"important.txt"});
  }
  // No temporary is left beside them.
  EXPECT_EQ(Entries(tmp_.path()), (std::vector<std::string>{"victim", "victim_f"}));
}

TEST_P(PublishRace, EmptyDirectoryMadeAtNewTargetIsKept) {
  const std::string s_dir = tmp_ / "s";
  Status s = WriteRacing(s_dir, {}, [&] { fs::create_directory(s_dir); });
  EXPECT_TRUE(Contains(s.message(), "already exists")) << s.ToString();
  EXPECT_TRUE(fs::is_directory(s_dir) && fs::is_empty(s_dir));
}

TEST_P(PublishRace, FileMadeAtNewTargetIsKept) {
  const std::string s_dir = tmp_ / "s";
  Status s = WriteRacing(s_dir, {}, [&] { storage_test::WriteFile(s_dir, "mine"); });
  EXPECT_TRUE(Contains(s.message(), "already exists")) << s.ToString();
  EXPECT_EQ(storage_test::ReadFile(s_dir), "mine");
}

// Two writers into one new path: the first to publish wins, the second
// fails and replaces nothing.
TEST_P(PublishRace, SecondWriterToNewPathFails) {
  const std::string dir = tmp_ / "s";
  Status s = WriteRacing(dir, {}, [&] {  // the other writer publishes first
    ASSERT_TRUE(storage_test::WriteVoxels(dir, a_, meta_).ok());
  });
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
  EXPECT_TRUE(Contains(s.message(), "already exists")) << s.ToString();
  EXPECT_EQ(VoxelsAt(dir), a_.size());
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"s"});
}

TEST_P(PublishRace, ForceReplacesTheCheckedStore) {
  const std::string dir = tmp_ / "s";
  ASSERT_TRUE(storage_test::WriteVoxels(dir, a_, meta_).ok());
  WriteOptions wo;
  wo.force = true;
  ASSERT_TRUE(WriteRacing(dir, wo, [] {}).ok());
  EXPECT_EQ(VoxelsAt(dir), b_.size());
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"s"});
}

TEST_P(PublishRace, ForceKeepsAStoreThatGainedAFile) {
  const std::string dir = tmp_ / "s";
  ASSERT_TRUE(storage_test::WriteVoxels(dir, a_, meta_).ok());
  WriteOptions wo;
  wo.force = true;
  Status s = WriteRacing(dir, wo, [&] { storage_test::WriteFile(dir + "/important.txt", "x"); });
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
  EXPECT_TRUE(Contains(s.message(), "changed after it was checked") &&
              Contains(s.message(), "important.txt"))
      << s.ToString();
  EXPECT_EQ(storage_test::ReadFile(dir + "/important.txt"), "x");
  fs::remove(dir + "/important.txt");
  EXPECT_EQ(VoxelsAt(dir), a_.size());
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"s"});
}

TEST_P(PublishRace, ForceKeepsAnotherStorePutInItsPlace) {
  const std::string dir = tmp_ / "s", moved = tmp_ / "moved";
  ASSERT_TRUE(storage_test::WriteVoxels(dir, a_, meta_).ok());
  WriteOptions wo;
  wo.force = true;
  Status s = WriteRacing(dir, wo, [&] {
    fs::rename(dir, moved);  // the checked store goes; another, same content, comes
    fs::create_directory(dir);
    fs::copy(moved, dir, fs::copy_options::recursive);
  });
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
  EXPECT_TRUE(Contains(s.message(), "not the directory found there before")) << s.ToString();
  EXPECT_EQ(VoxelsAt(dir), a_.size());
  EXPECT_EQ(VoxelsAt(moved), a_.size());
  EXPECT_EQ(Entries(tmp_.path()), (std::vector<std::string>{"moved", "s"}));
}

TEST_P(PublishRace, ForceKeepsADirectoryThatReplacedAnEmptyOne) {
  const std::string dir = tmp_ / "s";
  fs::create_directory(dir);
  WriteOptions wo;
  wo.force = true;
  Status s = WriteRacing(dir, wo, [&] {
    fs::remove(dir);
    fs::create_directory(dir);
    storage_test::WriteFile(dir + "/important.txt", "x");
  });
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.ToString();
  EXPECT_EQ(storage_test::ReadFile(dir + "/important.txt"), "x");
}

// Outputs (EXR, PNG, JSON) replace the file found at Create, nothing else.
TEST_P(PublishRace, OutputReplacesTheCheckedFile) {
  const std::string out = tmp_ / "o.exr";
  storage_test::WriteFile(out, "old");
  auto f = AtomicFile::Create(out);
  ASSERT_TRUE(f.ok());
  storage_test::WriteFile(f->temp_path(), "new");
  ASSERT_TRUE(f->Commit().ok());
  EXPECT_EQ(storage_test::ReadFile(out), "new");
  EXPECT_EQ(Entries(tmp_.path()), std::vector<std::string>{"o.exr"});
}

TEST_P(PublishRace, OutputNeverReplacesWhatAppearedAfterCreate) {
  struct Case {
    bool existed;                                 // a file at the path at Create
    std::function<void(const std::string&)> put;  // what is there at Commit
    std::string kept;                             // an entry that must stay
  };
  const std::vector<Case> cases = {
      {false,
       [](const std::string& p) {
         fs::create_directory(p);
         storage_test::WriteFile(p + "/important.txt", "x");
       },
       "/important.txt"},
      {false, [](const std::string& p) { storage_test::WriteFile(p, "x"); }, ""},
      {true,
       [](const std::string& p) {
         fs::remove(p);
         fs::create_directory(p);
         storage_test::WriteFile(p + "/important.txt", "x");
       },
       "/important.txt"},
      {true,
       [](const std::string& p) {
         fs::rename(p, p + ".moved");       // kept, so that its inode is not reused
         storage_test::WriteFile(p, "x");  // another file of the same name
       },
       ""},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string out = tmp_ / ("o" + std::to_string(i++) + ".exr");
    if (c.existed) storage_test::WriteFile(out, "old");
    auto f = AtomicFile::Create(out);
    ASSERT_TRUE(f.ok());
    storage_test::WriteFile(f->temp_path(), "new");
    c.put(out);
    Status s = f->Commit();
    EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
    EXPECT_TRUE(Contains(s.message(), c.existed ? "changed after it was checked" : "already exists"))
        << s.ToString();
    EXPECT_EQ(storage_test::ReadFile(out + c.kept), "x") << out;
  }
  // The temporaries are gone.
  for (const std::string& e : Entries(tmp_.path())) EXPECT_EQ(e[0], 'o') << e;
  EXPECT_EQ(storage_test::ReadFile(tmp_ / "o3.exr.moved"), "old");
}

INSTANTIATE_TEST_SUITE_P(RenameFlags, PublishRace, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "Fallback" : "Renameat2"; });

// Opens FIFO `path` for writing once its reader is there (the writer at its
// publish), within 120 s.
int OpenGate(const std::string& path) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (std::chrono::steady_clock::now() < end) {
    const int fd = open(path.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd >= 0 || errno != ENXIO) return fd;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return -1;
}

// Two vox-gen runs into one new path without --force, both past their check
// before either publishes: the first publishes, the second fails.
TEST(PublishRaceCli, SecondGenIntoNewPathFails) {
  TempDir tmp;
  const std::string gate1 = tmp / "gate1", gate2 = tmp / "gate2", out = tmp / "s";
  ASSERT_EQ(mkfifo(gate1.c_str(), 0600), 0);
  ASSERT_EQ(mkfifo(gate2.c_str(), 0600), 0);
  auto gen = [&](const std::string& gate) {
    return "VOX_TEST_PUBLISH_GATE=" + gate + " " + VOX_GEN_BIN + " sphere " + out +
           " --size 32 --quiet";
  };
  testing::CommandResult r1, r2;
  std::thread t1([&] { r1 = testing::RunCommand(gen(gate1)); });
  std::thread t2([&] { r2 = testing::RunCommand(gen(gate2)); });
  const int g1 = OpenGate(gate1), g2 = OpenGate(gate2);  // both checked, both waiting
  ASSERT_GE(g1, 0);
  ASSERT_GE(g2, 0);
  close(g1);  // the first publishes
  t1.join();
  close(g2);  // then the second tries
  t2.join();
  EXPECT_EQ(r1.code, 0) << r1.output;
  EXPECT_EQ(r2.code, 1) << r2.output;
  EXPECT_TRUE(Contains(r2.output, "already exists")) << r2.output;
  auto st = Store::Open(out, {});
  EXPECT_TRUE(st.ok());
}

}  // namespace
}  // namespace vox

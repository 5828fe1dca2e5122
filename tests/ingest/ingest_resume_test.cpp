// vox-ingest --resume: a real ingest killed (SIGKILL) or interrupted
// (SIGTERM) part-way leaves no store at the target and its verified bricks
// in `.NAME.resume`; the next --resume run keeps them (its message counts
// them), writes the rest and publishes the store an uninterrupted run makes
// (the same metadata, voxels, bricks and pyramid). A brick whose bytes do not
// match its journal record is written again; a journal of another ingest
// (another threshold), or one without bricks, is started over. Interrupted
// with the store complete (its index and pyramid written, about to be
// published), the directory keeps its journal, is refused as a store, and
// the next run publishes it. A `.NAME.resume` vox did not make (a file of
// the user's in it, a symbolic link) is refused, never emptied.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "storage/store.h"
#include "tests/common/run_command.h"
#include "tests/common/spawn.h"
#include "tests/ingest/ingest_test_util.h"
#include "tests/ingest/same_store.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
constexpr int64_t kN = 160;  // a float32 array of 160^3: 125 bricks of 32^3

// Journal records so far (storage/internal/brick_journal.h: a header of 24
// bytes, the key, a CRC; then 84-byte records), or -1 without a journal.
int64_t JournalRecords(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) return -1;
  char head[20];
  int64_t records = -1;
  struct stat st;
  if (::pread(fd, head, sizeof head, 0) == ssize_t(sizeof head) && ::fstat(fd, &st) == 0) {
    uint32_t key;
    std::memcpy(&key, head + 16, 4);
    records = (int64_t(st.st_size) - 24 - int64_t(key)) / 84;
  }
  ::close(fd);
  return records;
}

// Cuts a journal after its header: a journal of no brick.
void CutJournal(const std::string& path) {
  const int64_t records = JournalRecords(path);
  ASSERT_GE(records, 0);
  fs::resize_file(path, fs::file_size(path) - uint64_t(records) * 84);
  ASSERT_EQ(JournalRecords(path), 0);
}

class IngestResumeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    raw_ = dir_.File("cloud.raw");
    std::vector<float> v(size_t(kN * kN * kN));
    for (int64_t i = 0; i < kN; ++i)
      for (int64_t j = 0; j < kN; ++j)
        for (int64_t k = 0; k < kN; ++k)
          v[size_t((i * kN + j) * kN + k)] = float(
              0.5 + 0.3 * std::sin(0.21 * i) * std::cos(0.17 * j) + 0.2 * std::sin(0.3 * k + i));
    std::FILE* f = std::fopen(raw_.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(std::fwrite(v.data(), sizeof(float), v.size(), f), v.size());
    ASSERT_EQ(std::fclose(f), 0);
  }
  std::vector<std::string> Args(const std::string& out, const std::string& threshold) {
    return {VOX_INGEST_BINARY,
            raw_,
            out,
            "--shape",
            "160,160,160",
            "--dtype",
            "float32",
            "--threshold",
            threshold,
            "--threads",
            "1",
            "--zstd-level",
            "19",
            "--resume"};
  }
  static std::string Shell(const std::vector<std::string>& args) {
    std::string cmd;
    for (const std::string& a : args) cmd += "'" + a + "' ";
    return cmd + "2>&1";
  }
  // Starts a resumable ingest of `out` and signals it once its journal
  // holds `records` bricks; returns the records the journal held then.
  int64_t StartAndStop(const std::string& out, int sig, int64_t records, int* status) {
    const std::string journal =
        dir_.File("." + fs::path(out).filename().string() + ".resume/journal");
    const pid_t pid = testing::SpawnInGroup(Args(out, "0.6"));
    EXPECT_GT(pid, 0);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    int64_t seen = -1;
    while ((seen = JournalRecords(journal)) < records &&
           std::chrono::steady_clock::now() < deadline && waitpid(pid, status, WNOHANG) == 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    ::kill(sig == SIGKILL ? -pid : pid, sig);
    EXPECT_EQ(waitpid(pid, status, 0), pid);
    return seen;
  }
  testutil::TempDir dir_;
  std::string raw_;
};

TEST_F(IngestResumeTest, KilledMidwayThenResumedIsTheUninterruptedStore) {
  const std::string ref = dir_.File("ref.store"), out = dir_.File("out.store");
  const std::string resume_dir = dir_.File(".out.store.resume");
  auto whole = testing::RunCommand(Shell(Args(ref, "0.6")) + " --quiet");
  ASSERT_EQ(whole.code, 0) << whole.output;
  EXPECT_FALSE(fs::exists(dir_.File(".ref.store.resume")));

  int status = 0;
  const int64_t seen = StartAndStop(out, SIGKILL, 30, &status);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "the ingest ended first";
  ASSERT_GE(seen, 30);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(testing::TempEntries(dir_.path()).empty());
  ASSERT_TRUE(fs::exists(resume_dir + "/journal"));
  EXPECT_FALSE(fs::exists(resume_dir + "/index.vxi"));  // never a store that looks valid
  // The last brick's bytes damaged: its record no longer verifies.
  const std::string bricks = resume_dir + "/bricks.vxb";
  fs::resize_file(bricks, fs::file_size(bricks) - 3);
  const int64_t journaled = JournalRecords(resume_dir + "/journal");

  auto resumed = testing::RunCommand(Shell(Args(out, "0.6")));
  ASSERT_EQ(resumed.code, 0) << resumed.output;
  const size_t at = resumed.output.find("resuming: ");
  ASSERT_NE(at, std::string::npos) << resumed.output;
  const int64_t kept = std::atoll(resumed.output.c_str() + at + 10);
  EXPECT_GE(kept, 29);
  EXPECT_LT(kept, journaled);  // the damaged brick (at least) is written again
  EXPECT_FALSE(fs::exists(resume_dir));
  EXPECT_TRUE(testing::TempEntries(dir_.path()).empty());
  EXPECT_GT(testutil::ExpectSameStoreAndPyramid(ref, out), 0u);
}

TEST_F(IngestResumeTest, TerminatedKeepsTheBricksAndAnotherIngestStartsOver) {
  const std::string out = dir_.File("out.store"), resume_dir = dir_.File(".out.store.resume");
  int status = 0;
  StartAndStop(out, SIGTERM, 10, &status);
  ASSERT_TRUE(WIFEXITED(status)) << status;
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_GE(JournalRecords(resume_dir + "/journal"), 10);
  // Another threshold: another store, whose run starts over.
  auto other = testing::RunCommand(Shell(Args(out, "0.7")));
  ASSERT_EQ(other.code, 0) << other.output;
  EXPECT_NE(other.output.find("starting over"), std::string::npos) << other.output;
  auto fresh = testing::RunCommand(Shell(Args(dir_.File("fresh.store"), "0.7")) + " --quiet");
  ASSERT_EQ(fresh.code, 0) << fresh.output;
  EXPECT_GT(testutil::ExpectSameStoreAndPyramid(dir_.File("fresh.store"), out), 0u);
}

TEST_F(IngestResumeTest, TheSignalMessageNamesWhatIsKept) {
  const std::string out = dir_.File("out.store");
  auto r = testing::RunCommand("(" + Shell(Args(out, "0.6")) + " & p=$!; while [ ! -e '" +
                               dir_.File(".out.store.resume/journal") +
                               "' ]; do sleep 0.01; done; kill -INT $p; wait $p)");
  EXPECT_EQ(r.code, 128 + SIGINT) << r.output;
  EXPECT_NE(
      r.output.find("the bricks written so far are kept in '" + dir_.File(".out.store.resume") +
                    "': run it again with --resume to continue"),
      std::string::npos)
      << r.output;
}

TEST_F(IngestResumeTest, AJournalOfNoBrickStartsOver) {
  const std::string out = dir_.File("out.store"), resume_dir = dir_.File(".out.store.resume");
  int status = 0;
  StartAndStop(out, SIGKILL, 0, &status);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "the ingest ended first";
  CutJournal(resume_dir + "/journal");
  auto resumed = testing::RunCommand(Shell(Args(out, "0.6")));
  ASSERT_EQ(resumed.code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("starting over: the earlier run in '" + resume_dir +
                                "' kept no brick"),
            std::string::npos)
      << resumed.output;
  EXPECT_FALSE(fs::exists(resume_dir));
  auto store = Store::Open(out, OpenOptions{});
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  EXPECT_GT((*store)->meta().brick_count, 30u);
}

TEST_F(IngestResumeTest, InterruptedWhenCompleteThenResumedPublishes) {
  const std::string ref = dir_.File("ref.store"), out = dir_.File("out.store");
  const std::string resume_dir = dir_.File(".out.store.resume"), gate = dir_.File("gate");
  auto whole = testing::RunCommand(Shell(Args(ref, "0.6")) + " --quiet");
  ASSERT_EQ(whole.code, 0) << whole.output;
  uint64_t bricks = 0;
  {
    auto s = Store::Open(ref, OpenOptions{});
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    bricks = (*s)->meta().brick_count;
  }
  ASSERT_EQ(::mkfifo(gate.c_str(), 0600), 0);
  // The ingest stops at the gate (its index and pyramid written, just before
  // publishing) until a writer opens the gate and closes it; it is
  // terminated there, the gate held open until it has exited (an ingest
  // that never reaches the gate fails the test after 120 s, not hangs it).
  auto r = testing::RunCommand(
      "(VOX_TEST_PUBLISH_GATE='" + gate + "' " + Shell(Args(out, "0.6")) +
      " & p=$!; timeout 120 sh -c 'exec 3>\"$0\"; kill -TERM \"$1\"; "
      "while kill -0 \"$1\" 2>/dev/null; do sleep 0.05; done' '" + gate + "' $p; wait $p)");
  EXPECT_EQ(r.code, 128 + SIGTERM) << r.output;
  EXPECT_NE(r.output.find("the bricks written so far are kept in '" + resume_dir +
                          "': run it again with --resume to continue"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(out));
  ASSERT_TRUE(fs::exists(resume_dir + "/index.vxi")) << "not stopped at the gate";
  EXPECT_EQ(JournalRecords(resume_dir + "/journal"), int64_t(bricks));
  auto unfinished = Store::Open(resume_dir, OpenOptions{});
  ASSERT_FALSE(unfinished.ok());
  EXPECT_NE(unfinished.status().message().find("unfinished resumable ingest"), std::string::npos)
      << unfinished.status().ToString();
  fs::remove(gate);

  auto resumed = testing::RunCommand(Shell(Args(out, "0.6")));
  ASSERT_EQ(resumed.code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resuming: " + std::to_string(bricks) + " bricks"),
            std::string::npos)
      << resumed.output;
  EXPECT_FALSE(fs::exists(resume_dir));
  EXPECT_GT(testutil::ExpectSameStoreAndPyramid(ref, out), 0u);
}

TEST_F(IngestResumeTest, ADirectoryVoxDidNotMakeIsRefusedNotEmptied) {
  const std::string out = dir_.File("out.store"), resume_dir = dir_.File(".out.store.resume");
  fs::create_directory(resume_dir);
  const std::string notes = resume_dir + "/notes.txt";
  { std::FILE* f = std::fopen(notes.c_str(), "w"); ASSERT_NE(f, nullptr); std::fclose(f); }
  auto r = testing::RunCommand(Shell(Args(out, "0.6")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("holds 'notes.txt' but no journal"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(notes));
  EXPECT_FALSE(fs::exists(out));

  // A symbolic link in its place, to a directory of the user's.
  fs::rename(resume_dir, dir_.File("mine"));
  fs::create_directory_symlink(dir_.File("mine"), resume_dir);
  r = testing::RunCommand(Shell(Args(out, "0.6")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("is not a directory (a symbolic link)"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(dir_.File("mine/notes.txt")));
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace vox

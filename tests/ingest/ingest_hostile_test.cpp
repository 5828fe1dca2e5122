// vox-ingest on hostile input: a crash inside the reader (a signal in the
// ingest's child process) becomes a clear error naming the file, exit 1 and
// no temporary store; byte-mutated and truncated .vdb files never crash the
// tool; active tiles that would expand past --max-voxels are refused; an
// absurd --threads is refused.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "storage/store.h"
#include "tests/common/run_command.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

using Result = testing::CommandResult;

// Runs vox-ingest with `env` prepended (a shell assignment list), stderr
// folded into the output. A sanitizer build must let a crash be a crash.
Result RunIngest(const std::string& args, const std::string& env = "") {
  return testing::RunCommand("ASAN_OPTIONS=handle_segv=0:handle_sigbus=0:handle_abort=0 " + env +
                             " " + VOX_INGEST_BINARY + " " + args);
}

std::vector<std::string> Leftovers(const std::string& dir) {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos)
      v.push_back(e.path().filename().string());
  return v;
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

class IngestHostileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        12.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
    grid->setName("sphere");
    vdb_ = dir_.File("in.vdb");
    testutil::WriteVdb(vdb_, {grid});
  }
  testutil::TempDir dir_;
  std::string vdb_;
};

// A crash of the child is a crash, named as one (the process, the signal),
// not a verdict on the file.
TEST_F(IngestHostileTest, ACrashWhileReadingIsReportedAndCleanedUp) {
  for (int sig : {SIGSEGV, SIGBUS}) {
    const std::string out = dir_.File("store");
    Result r = RunIngest(vdb_ + " " + out + " --quiet", "VOX_INGEST_TEST_CRASH=" + std::to_string(sig));
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_NE(r.output.find(vdb_ + ": the ingest child process (pid "), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find(std::string(") crashed with ") +
                            (sig == SIGSEGV ? "SIGSEGV" : "SIGBUS")),
              std::string::npos)
        << r.output;
    EXPECT_EQ(r.output.find("corrupt"), std::string::npos) << r.output;
    EXPECT_TRUE(Leftovers(dir_.path()).empty()) << "the child's temporary store was removed";
    EXPECT_FALSE(fs::exists(out));
  }
}

// A child that exits without finishing (as a sanitizer report makes it) is a
// crash too, with its exit code.
TEST_F(IngestHostileTest, AChildThatExitsWithoutFinishingIsACrash) {
  const std::string out = dir_.File("store");
  Result r = RunIngest(vdb_ + " " + out + " --quiet", "VOX_INGEST_TEST_EXIT=23");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find(vdb_ + ": the ingest child process (pid "), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("crashed: it exited with code 23 before finishing"), std::string::npos)
      << r.output;
  EXPECT_TRUE(Leftovers(dir_.path()).empty());
  EXPECT_FALSE(fs::exists(out));
}

// OpenVDB's own errors on a corrupt file stay its messages: no crash.
TEST_F(IngestHostileTest, ACorruptFileIsNotACrash) {
  const std::string in = dir_.File("bad.vdb"), out = dir_.File("store");
  std::ofstream(in, std::ios::binary) << "this is not a vdb file, only text";
  Result r = RunIngest(in + " " + out + " --quiet");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find(in), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("crashed"), std::string::npos) << r.output;
  EXPECT_TRUE(Leftovers(dir_.path()).empty());
}

TEST_F(IngestHostileTest, AnEarlierStoreSurvivesACrashedReplace) {
  const std::string out = dir_.File("store");
  ASSERT_EQ(RunIngest(vdb_ + " " + out + " --quiet").code, 0);
  auto before = Store::Open(out, {});
  ASSERT_TRUE(before.ok());
  const uint64_t id = (*before)->store_id();
  Result r = RunIngest(vdb_ + " " + out + " --quiet --force", "VOX_INGEST_TEST_CRASH=11");
  EXPECT_EQ(r.code, 1) << r.output;
  auto after = Store::Open(out, {});
  ASSERT_TRUE(after.ok()) << after.status().ToString();
  EXPECT_EQ((*after)->store_id(), id);
  EXPECT_TRUE(Leftovers(dir_.path()).empty());
}

// Byte mutations (seeded) and truncations of a real .vdb: every run either
// ingests (a valid store) or fails with exit 1 and a message naming the file;
// never a signal, never a temporary left. A crash inside OpenVDB shows as the
// crash of the child process. A fixed number of mutations, whatever the
// machine's load (the same files every run: the seed is fixed); the fuzzer
// goes further.
TEST_F(IngestHostileTest, MutatedAndTruncatedFilesNeverKillTheTool) {
  const std::string good = ReadBytes(vdb_);
  ASSERT_GT(good.size(), 1000u);
  std::mt19937_64 rng(20261201);
  constexpr int kMutations = 40;  // 5 of them truncations
  int runs = 0, ingested = 0, refused = 0, crashes = 0;
  for (int i = 0; i < kMutations; ++i) {
    std::string bytes = good;
    if (i % 8 == 7) {
      bytes.resize(std::uniform_int_distribution<size_t>(1, good.size() - 1)(rng));
    } else {
      const int flips = 1 + int(rng() % 4);
      for (int f = 0; f < flips; ++f) {
        const size_t at = std::uniform_int_distribution<size_t>(0, good.size() - 1)(rng);
        const uint8_t values[] = {0x00, 0x80, 0xff, 0x7f, uint8_t(rng())};
        bytes[at] = char(values[rng() % 5]);
      }
    }
    const std::string in = dir_.File("m.vdb"), out = dir_.File("m-store");
    std::ofstream(in, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    Result r = RunIngest(in + " " + out + " --quiet --threads 2");
    ++runs;
    ASSERT_TRUE(r.code == 0 || r.code == 1) << "mutation " << i << ": exit "
                                                       << r.code << "\n" << r.output;
    if (r.code == 0) {
      ++ingested;
      EXPECT_TRUE(Store::Open(out, {}).ok()) << "mutation " << i;
    } else {
      EXPECT_NE(r.output.find(in), std::string::npos) << "mutation " << i << ": " << r.output;
      EXPECT_FALSE(fs::exists(out)) << "mutation " << i;
      if (r.output.find("the ingest child process") != std::string::npos) ++crashes;
      else ++refused;
    }
    ASSERT_TRUE(Leftovers(dir_.path()).empty()) << "mutation " << i;
    fs::remove_all(out);
  }
  EXPECT_EQ(runs, kMutations);
  std::printf("%d mutated files: %d ingested, %d refused, %d crashes reported\n", runs,
              ingested, refused, crashes);
}

// A fog volume with one active tile covering a 4096^3 root block: 6.9e10
// voxels, refused by default naming --max-voxels; a smaller tile passes by
// default and is refused under a lower --max-voxels.
TEST_F(IngestHostileTest, TileExpansionIsLimited) {
  auto fog = openvdb::FloatGrid::create(0.0f);
  fog->setName("fog");
  fog->setGridClass(openvdb::GRID_FOG_VOLUME);
  fog->tree().addTile(/*level=*/3, openvdb::Coord(0), 1.0f, /*active=*/true);
  const std::string huge = dir_.File("huge.vdb");
  testutil::WriteVdb(huge, {fog});
  Result r = RunIngest(huge + " " + dir_.File("h") + " --quiet");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("--max-voxels"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("68719476736 voxels"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_.File("h")));

  auto small = openvdb::FloatGrid::create(0.0f);
  small->setName("fog");
  small->setGridClass(openvdb::GRID_FOG_VOLUME);
  small->tree().addTile(/*level=*/2, openvdb::Coord(0), 1.0f, /*active=*/true);  // 128^3
  const std::string tile = dir_.File("tile.vdb");
  testutil::WriteVdb(tile, {small});
  r = RunIngest(tile + " " + dir_.File("t1") + " --quiet --max-voxels 1000");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("2097152 voxels, more than the limit of 1000 (--max-voxels"),
            std::string::npos)
      << r.output;
  r = RunIngest(tile + " " + dir_.File("t2") + " --quiet");
  EXPECT_EQ(r.code, 0) << r.output;
  auto s = Store::Open(dir_.File("t2"), {});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->meta().voxel_count, 128u * 128u * 128u);
  for (const char* bad : {"0", "-5", "1.5", "x"}) {
    r = RunIngest(tile + " " + dir_.File("t3") + " --max-voxels " + bad);
    EXPECT_EQ(r.code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("--max-voxels"), std::string::npos) << r.output;
  }
}

TEST_F(IngestHostileTest, ThreadsAreCapped) {
  for (const char* n : {"1000000", "1025", "-1"}) {
    Result r = RunIngest(vdb_ + " " + dir_.File("s") + " --threads " + n);
    EXPECT_EQ(r.code, 2) << n << ": " << r.output;
    EXPECT_NE(r.output.find("--threads " + std::string(n) + ": must be in 1..1024"),
              std::string::npos)
        << r.output;
  }
  EXPECT_EQ(RunIngest(vdb_ + " " + dir_.File("s") + " --quiet --threads 64").code, 0);
}

}  // namespace
}  // namespace vox

// vox-ingest killed mid-ingest by SIGTERM (a Slurm time-out) or SIGINT:
// exits 128 + the signal and leaves no temporary store directory; a later
// run removes the temporary directory of a writer that was SIGKILLed.
// The ingest is held mid-way (after the writer created its temporary
// directory) by the tool's VOX_INGEST_TEST_STALL hook. Also: a dead
// --add-lod's pyramid temporary is stale, and an output holding its input is
// refused.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include "storage/store.h"
#include "tests/ingest/ingest_test_util.h"

extern char** environ;

namespace vox {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> Temporaries(const std::string& dir, const std::string& name) {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind("." + name + ".tmp-", 0) == 0)
      v.push_back(e.path().filename().string());
  return v;
}

class IngestSignalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        20.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
    grid->setName("sphere");
    vdb_ = dir_.File("in.vdb");
    testutil::WriteVdb(vdb_, {grid});
  }
  // Starts vox-ingest stalled mid-ingest; returns its pid once its temporary
  // store directory exists.
  // `err`: a file for its stderr (empty: the test's).
  pid_t StartStalled(const std::string& out, const std::string& err = "", bool force = false) {
    std::vector<std::string> args = {VOX_INGEST_BINARY, vdb_, out, "--quiet", "--threads", "2"};
    if (force) args.push_back("--force");
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::vector<std::string> env_s;
    for (char** e = environ; *e; ++e) env_s.push_back(*e);
    env_s.push_back("VOX_INGEST_TEST_STALL=1");
    std::vector<char*> envp;
    for (auto& e : env_s) envp.push_back(e.data());
    envp.push_back(nullptr);
    pid_t pid = -1;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    if (!err.empty())
      posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                       0644);
    const int spawned = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) return -1;
    const std::string name = fs::path(out).filename().string();
    for (int i = 0; i < 3000 && Temporaries(dir_.path(), name).empty(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // into the stall
    return pid;
  }
  testutil::TempDir dir_;
  std::string vdb_;
};

std::string Slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// The message says what was kept: nothing new, and a store --force was to
// replace as it was (byte for byte).
TEST_F(IngestSignalTest, TermAndIntRemoveTheTemporaryStore) {
  const std::string err = dir_.File("err.txt"), old = dir_.File("old");
  ASSERT_EQ(
      std::system((std::string(VOX_INGEST_BINARY) + " " + vdb_ + " " + old + " --quiet").c_str()),
      0);
  const std::string old_index = Slurp(old + "/index.vxi");
  ASSERT_FALSE(old_index.empty());
  for (int sig : {SIGTERM, SIGINT}) {
    for (bool replace : {false, true}) {
      const std::string out = replace ? old : dir_.File("store");
      const std::string name = fs::path(out).filename().string();
      pid_t pid = StartStalled(out, err, replace);
      ASSERT_GT(pid, 0);
      ASSERT_EQ(Temporaries(dir_.path(), name).size(), 1u) << "the ingest never started";
      ASSERT_EQ(kill(pid, sig), 0);
      int status = 0;
      ASSERT_EQ(waitpid(pid, &status, 0), pid);
      ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
      EXPECT_EQ(WEXITSTATUS(status), 128 + sig);
      EXPECT_TRUE(Temporaries(dir_.path(), name).empty());
      const std::string what = sig == SIGINT ? "interrupted (SIGINT)" : "terminated (SIGTERM)";
      if (replace) {
        EXPECT_EQ(Slurp(out + "/index.vxi"), old_index);
        EXPECT_EQ(Slurp(err), "vox-ingest: test stall\n\nvox-ingest: " + what +
                                  "; no store written: '" + out + "' is as it was before\n");
      } else {
        EXPECT_FALSE(fs::exists(out));
        EXPECT_EQ(Slurp(err), "vox-ingest: test stall\n\nvox-ingest: " + what +
                                  "; no store written at '" + out + "', nothing left behind\n");
      }
    }
  }
}

// The ingest runs in vox-ingest re-executed, not in a bare fork of it: the
// parent has library threads (log4cplus starts a pool when OpenVDB loads it),
// and a forked copy inherited a lock one of them held and hung, in CI under
// ASan. An exec'd worker has the tool's binary and VOX_INGEST_WORKER_FD in its
// own environment (/proc/PID/environ is the environment given to exec; a
// forked copy shows its parent's).
TEST_F(IngestSignalTest, TheIngestRunsInAReExecutedWorker) {
  const std::string out = dir_.File("store");
  pid_t pid = StartStalled(out);
  ASSERT_GT(pid, 0);
  const std::vector<std::string> tmp = Temporaries(dir_.path(), "store");
  ASSERT_EQ(tmp.size(), 1u) << "the ingest never started";
  // .store.tmp-PID-SUFFIX: the worker's pid.
  const std::string rest = tmp[0].substr(std::string(".store.tmp-").size());
  const pid_t worker = pid_t(std::stol(rest.substr(0, rest.find('-'))));
  EXPECT_NE(worker, pid);
  const std::string proc = "/proc/" + std::to_string(worker);
  EXPECT_EQ(fs::canonical(proc + "/exe"), fs::canonical(VOX_INGEST_BINARY));
  std::ifstream env_file(proc + "/environ", std::ios::binary);
  const std::string env((std::istreambuf_iterator<char>(env_file)),
                        std::istreambuf_iterator<char>());
  EXPECT_NE(env.find("VOX_INGEST_WORKER_FD="), std::string::npos);
  std::ifstream parent_file("/proc/" + std::to_string(pid) + "/environ", std::ios::binary);
  const std::string parent_env((std::istreambuf_iterator<char>(parent_file)),
                               std::istreambuf_iterator<char>());
  EXPECT_EQ(parent_env.find("VOX_INGEST_WORKER_FD="), std::string::npos);
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);
  EXPECT_TRUE(Temporaries(dir_.path(), "store").empty());
}

TEST_F(IngestSignalTest, ALaterRunRemovesTheTemporaryOfAKilledOne) {
  const std::string out = dir_.File("store");
  pid_t pid = StartStalled(out);
  ASSERT_GT(pid, 0);
  ASSERT_EQ(Temporaries(dir_.path(), "store").size(), 1u);
  ASSERT_EQ(kill(pid, SIGKILL), 0);  // no chance to clean up
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_EQ(Temporaries(dir_.path(), "store").size(), 1u);
  const std::string cmd = std::string(VOX_INGEST_BINARY) + " " + vdb_ + " " + out + " --quiet";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  EXPECT_TRUE(Temporaries(dir_.path(), "store").empty());
  EXPECT_TRUE(Store::Open(out, {}).ok());
}

// A pyramid temporary left in a store by a --add-lod that died
// (STORE/.lod.tmp-PID-*) is stale, not foreign data: --force replaces the
// store. A live process's one still stops it.
TEST_F(IngestSignalTest, AStalePyramidTemporaryDoesNotMakeTheStoreForeign) {
  const std::string out = dir_.File("store");
  const std::string cmd = std::string(VOX_INGEST_BINARY) + " " + vdb_ + " " + out + " --quiet";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const pid_t dead = fork();
  if (dead == 0) _exit(0);
  waitpid(dead, nullptr, 0);
  const std::string stale = out + "/.lod.tmp-" + std::to_string(dead) + "-0badf00d";
  fs::create_directories(stale + "/1");
  ASSERT_EQ(std::system((cmd + " --force").c_str()), 0) << "the store was taken as foreign";
  EXPECT_FALSE(fs::exists(stale));
  const std::string live = out + "/.lod.tmp-" + std::to_string(getpid()) + "-0badf00d";
  fs::create_directories(live);
  EXPECT_NE(std::system((cmd + " --force 2>/dev/null").c_str()), 0);
  EXPECT_TRUE(fs::exists(live));
}

// The output store must be neither the input nor a directory holding it.
TEST_F(IngestSignalTest, AnOutputHoldingTheInputIsRefused) {
  const std::string held = dir_.File("holder");
  fs::create_directories(held);
  fs::copy_file(vdb_, held + "/in.vdb");
  const std::string cmd =
      std::string(VOX_INGEST_BINARY) + " " + held + "/in.vdb " + held + " --force --quiet 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string output;
  char buf[512];
  while (fgets(buf, sizeof buf, p)) output += buf;
  EXPECT_NE(pclose(p), 0);
  EXPECT_NE(output.find("holds the input"), std::string::npos) << output;
  EXPECT_TRUE(fs::exists(held + "/in.vdb"));
}

}  // namespace
}  // namespace vox

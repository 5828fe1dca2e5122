// The kill harness: vox-ingest (and its ingest child) SIGKILLed at random
// points of a run, many times (VOX_KILL_POINTS, default 200; the "long"
// registration 1000). After each kill the target is the previous complete
// store, or a complete new one, or (when there was none) absent: never a half
// store. Temporary directories a kill leaves are removed by the next run.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "storage/store.h"
#include "tests/common/spawn.h"
#include "tests/ingest/ingest_test_util.h"

extern char** environ;

namespace vox {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A complete store: opens, and every brick decodes.
bool Complete(const std::string& dir, uint64_t* id) {
  auto s = Store::Open(dir, {});
  if (!s.ok()) return false;
  for (uint32_t b = 0; b < (*s)->meta().brick_count; ++b)
    if (!(*s)->FetchBrick(b).ok()) return false;
  *id = (*s)->store_id();
  return true;
}

TEST(IngestKill, SigkillAtRandomPointsNeverLeavesAHalfStore) {
  openvdb::initialize();
  testutil::TempDir dir;
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(24.0f, openvdb::Vec3f(0.0f),
                                                                       1.0f, 3.0f);
  grid->setName("sphere");
  const std::string vdb = dir.File("in.vdb"), out = dir.File("store");
  testutil::WriteVdb(vdb, {grid});
  const std::vector<std::string> args = {VOX_INGEST_BINARY, vdb, out, "--quiet", "--force",
                                         "--threads", "2"};
  // One clean run: how long a run takes bounds the kill points.
  const auto t0 = Clock::now();
  pid_t pid = testing::SpawnInGroup(args);
  ASSERT_GT(pid, 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  const double run_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
  uint64_t current = 0;
  ASSERT_TRUE(Complete(out, &current));

  const char* env = std::getenv("VOX_KILL_POINTS");
  const int points = env ? std::atoi(env) : 200;
  std::mt19937_64 rng(7);
  int kept = 0, replaced = 0, absent = 0, finished_first = 0;
  for (int i = 0; i < points; ++i) {
    if (i % 10 == 9) fs::remove_all(out);  // also: a first ingest killed
    const bool had_store = fs::exists(out);
    const auto delay = std::chrono::microseconds(
        int64_t(std::uniform_real_distribution<double>(0.0, 1.1 * run_us)(rng)));
    pid = testing::SpawnInGroup(args);
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(delay);
    kill(-pid, SIGKILL);
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    finished_first += WIFEXITED(status);
    uint64_t id = 0;
    if (!fs::exists(out)) {
      ASSERT_FALSE(had_store) << "kill point " << i << ": the previous store vanished";
      ++absent;
      continue;
    }
    ASSERT_TRUE(Complete(out, &id)) << "kill point " << i << " (" << delay.count()
                                    << " us): a half store at the target";
    if (had_store && id == current) {
      ++kept;
    } else {
      ++replaced;
      current = id;
    }
  }
  std::printf("%d kill points over %.0f us runs: %d kept the previous store, %d replaced it, "
              "%d absent, %d finished before the kill\n",
              points, run_us, kept, replaced, absent, finished_first);
  // A later run cleans up every temporary the kills left.
  pid = testing::SpawnInGroup(args);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_TRUE(testing::TempEntries(dir.path()).empty());
  EXPECT_GT(kept + absent, 0) << "no kill landed mid-run";
}

}  // namespace
}  // namespace vox

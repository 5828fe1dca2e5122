// `vox-ingest --add-lod STORE` stopped by SIGTERM or SIGINT exits
// 128 + the signal and removes its pyramid temporary (STORE/.lod.tmp-PID-*);
// the store stays as it was, and a later --add-lod succeeds.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "tests/common/spawn.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

bool HasPyramidTemporary(const std::string& store) {
  for (const auto& e : fs::directory_iterator(store))
    if (e.path().filename().string().rfind(".lod.tmp-", 0) == 0) return true;
  return false;
}

TEST(AddLodSignal, TermAndIntRemoveThePyramidTemporary) {
  char tmpl[] = "/tmp/vox-add-lod-XXXXXX";
  ASSERT_NE(mkdtemp(tmpl), nullptr);
  const std::string dir = tmpl, store = dir + "/store";
  const std::string gen =
      std::string(VOX_GEN_BIN) + " sphere " + store + " --size 512 --no-lod --quiet";
  ASSERT_EQ(std::system(gen.c_str()), 0);
  int handled = 0;
  for (int sig : {SIGTERM, SIGINT}) {
    const pid_t pid = testing::SpawnInGroup({VOX_INGEST_BIN, "--add-lod", store, "--quiet"});
    ASSERT_GT(pid, 0);
    bool seen = false;
    for (int i = 0; i < 20000 && !seen; ++i) {
      seen = HasPyramidTemporary(store);
      if (!seen) std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    kill(pid, sig);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status));
    if (WEXITSTATUS(status) == 0) {  // finished first: nothing to judge
      fs::remove_all(store + "/lod");
      continue;
    }
    EXPECT_EQ(WEXITSTATUS(status), 128 + sig);
    EXPECT_FALSE(HasPyramidTemporary(store)) << "signal " << sig << " left the temporary";
    EXPECT_FALSE(fs::exists(store + "/lod"));
    ++handled;
  }
  EXPECT_GT(handled, 0) << "every --add-lod finished before its signal";
  const std::string add = std::string(VOX_INGEST_BIN) + " --add-lod " + store + " --quiet";
  EXPECT_EQ(std::system(add.c_str()), 0);
  EXPECT_TRUE(fs::is_directory(store + "/lod"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace vox

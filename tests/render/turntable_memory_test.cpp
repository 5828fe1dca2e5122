// A turntable of the most frames a sequence may have (--turntable 1000000)
// makes each frame's camera and output paths when the frame comes, and
// checks its output patterns once, not frame by frame: in a 64 MiB memory
// cgroup it starts rendering within 2 s, whether it renders one frame
// (--frames 1) or all of them (stopped by SIGINT after its first frames).
// Needs a writable memory cgroup (root); skipped otherwise.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "tests/common/cgroup_util.h"
#include "tests/render/store_suite.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;

class TurntableMemoryTest : public SphereShellStoreSuite {
 protected:
  // Runs vox-render with `args` in a 64 MiB cgroup (stopped by SIGINT after
  // `stop_after` s, if it runs that long); returns the seconds until it
  // said it renders frame 1 (-1: never) and sets `result` and `log`.
  double RunUntilFrameOne(const std::vector<std::string>& args, int stop_after,
                          CgroupRunResult* result, std::string* log) {
    const std::string err = Path("stderr.txt");
    fs::remove(err);
    std::vector<std::string> argv = {"/usr/bin/timeout", "--preserve-status", "-s", "INT", std::to_string(stop_after),
                                     VOX_RENDER_BIN, Path("store"), "--threads", "1",
                                     "--size", "16x16", "--tile-size", "16"};
    argv.insert(argv.end(), args.begin(), args.end());
    CgroupRunOptions o;
    o.limit_bytes = 64 * kMiB;
    o.stderr_path = err;
    const auto t0 = std::chrono::steady_clock::now();
    std::atomic<bool> done{false};
    std::thread run([&] {
      auto r = RunInMemoryCgroup(argv, o);
      if (r.ok()) *result = *r;
      done = true;
    });
    double seen = -1;
    while (seen < 0) {
      const bool finished = done.load();
      if (ReadAll(err).find("frame 1/1000000") != std::string::npos)
        seen = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (finished) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    run.join();
    *log = ReadAll(err);
    return seen;
  }
};

TEST_F(TurntableMemoryTest, OneFrameOfAMillionStartsAtOnceIn64MiB) {
  VOX_REQUIRE_MEMORY_CGROUP();
  CgroupRunResult r;
  std::string log;
  const double seen = RunUntilFrameOne(
      {"--turntable", "1000000", "--frames", "1", "-o", Path("one.%07d.exr")}, 60, &r, &log);
  EXPECT_EQ(r.exit_code, 0) << r.Describe() << "\n" << log;
  EXPECT_FALSE(r.oom_killed) << r.Describe();
  EXPECT_GE(seen, 0.0) << log;
  EXPECT_LT(seen, 2.0) << log;
  EXPECT_TRUE(fs::exists(Path("one.0000001.exr"))) << log;
  EXPECT_FALSE(fs::exists(Path("one.0000002.exr")));
}

TEST_F(TurntableMemoryTest, AllMillionFramesStartAtOnceIn64MiB) {
  VOX_REQUIRE_MEMORY_CGROUP();
  CgroupRunResult r;
  std::string log;
  const double seen =
      RunUntilFrameOne({"--turntable", "1000000", "-o", Path("all.%07d.exr")}, 4, &r, &log);
  EXPECT_FALSE(r.oom_killed) << r.Describe();
  EXPECT_EQ(r.exit_code, 130) << r.Describe() << "\n" << log;  // SIGINT's, after some frames
  EXPECT_GE(seen, 0.0) << log;
  EXPECT_LT(seen, 2.0) << log;
  EXPECT_TRUE(fs::exists(Path("all.0000001.exr"))) << log;
}

}  // namespace
}  // namespace vox::testing

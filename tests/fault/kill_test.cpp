// The kill harness for vox-render and vox-merge: each tool SIGKILLed at
// random points of a run, many times (VOX_KILL_POINTS per case, default 100;
// the "long" registration 1000). Cases: a whole frame rendered over an
// existing good out.exr, a --tiles part rendered over an existing part, and a
// merge over an existing merged image. After each kill the output is the
// earlier file byte for byte, or a complete new one with the reference's
// pixels (the kill came after the rename; a part is judged by merging it with
// the other parts), or absent when there was none:
// never a partial file. The temporaries kills leave (`.NAME.tmp-PID-XXXXXX`)
// are removed by the next run of the tool for the same output, and only
// those: a live process's temporary and other files stay. SIGTERM and SIGINT
// at random points of a render and a merge end them with 128 + the signal,
// their temporaries removed and the output the earlier one or a whole new one.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "render/exr.h"
#include "render/merge.h"
#include "tests/common/run_command.h"
#include "tests/common/spawn.h"

extern char** environ;

namespace vox {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// Runs to the end; returns the wall time in microseconds, or -1 on failure.
double RunToEnd(const std::vector<std::string>& args) {
  const auto t0 = Clock::now();
  const pid_t pid = testing::SpawnInGroup(args);
  if (pid <= 0) return -1;
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return -1;
  return std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
}

// The pid of a process that has exited and been reaped.
long DeadPid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return long(pid);
}

class Kill : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/vox-kill-XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    store_ = dir_ + "/store";
    testing::CommandResult r =
        testing::RunCommand(std::string(VOX_GEN_BIN) + " sphere " + store_ + " --size 64 --quiet");
    ASSERT_EQ(r.code, 0) << r.output;
    const char* env = std::getenv("VOX_KILL_POINTS");
    points_ = env ? std::atoi(env) : 100;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::vector<std::string> Render(const std::string& out, const std::string& tiles = "") {
    std::vector<std::string> a = {
        VOX_RENDER_BIN, store_, "--size", "256x192", "--tile-size", "16", "--quiet",
        "--threads",    "2",    "-o",     out};
    if (!tiles.empty()) a.insert(a.end(), {"--tiles", tiles});
    return a;
  }

  // Reads the image an output stands for: the whole frame it holds, or for a
  // part the frame merged from it and the other parts.
  using Reader = std::function<StatusOr<ExrImage>(const std::string&)>;

  // Runs `args` (writing `out`) once to the end for the reference pixels,
  // then kills it at points_ random moments within 1.1 run times. Every
  // tenth point starts without an earlier output (the next one has it again).
  void KillAtRandomPoints(const std::vector<std::string>& args, const std::string& out,
                          uint64_t seed, const Reader& read = ReadExr) {
    const double run_us = RunToEnd(args);
    ASSERT_GT(run_us, 0) << "the tool failed on its own";
    auto ref = read(out);
    ASSERT_TRUE(ref.ok()) << ref.status().ToString();
    ASSERT_TRUE(ref->info.complete);
    std::string previous = Slurp(out);
    std::mt19937_64 rng(seed);
    int kept = 0, replaced = 0, absent = 0, finished = 0, left_temps = 0;
    for (int i = 0; i < points_; ++i) {
      if (i % 10 == 9) {
        fs::remove(out);  // a first run killed
      } else if (!fs::exists(out)) {
        std::ofstream(out, std::ios::binary) << previous;  // the earlier output again
      }
      const bool had_output = fs::exists(out);
      const auto delay = std::chrono::microseconds(
          int64_t(std::uniform_real_distribution<double>(0.0, 1.1 * run_us)(rng)));
      const pid_t pid = testing::SpawnInGroup(args);
      ASSERT_GT(pid, 0);
      std::this_thread::sleep_for(delay);
      kill(-pid, SIGKILL);
      int status = 0;
      ASSERT_EQ(waitpid(pid, &status, 0), pid);
      finished += WIFEXITED(status);
      if (WIFEXITED(status)) {
        ASSERT_EQ(WEXITSTATUS(status), 0) << "kill point " << i;
      }
      left_temps += !testing::TempEntries(dir_).empty();
      if (!fs::exists(out)) {
        ASSERT_FALSE(had_output) << "kill point " << i << ": the earlier output vanished";
        ++absent;
        continue;
      }
      const std::string now = Slurp(out);
      if (had_output && now == previous) {
        ++kept;
        continue;
      }
      // Not the earlier file: it must be a complete new one.
      auto img = read(out);
      ASSERT_TRUE(img.ok()) << "kill point " << i << " (" << delay.count()
                            << " us): a broken output: " << img.status().ToString();
      ASSERT_TRUE(img->info.complete) << "kill point " << i << ": an incomplete output";
      ASSERT_EQ(img->pixels, ref->pixels) << "kill point " << i << ": other pixels";
      previous = now;
      ++replaced;
    }
    std::printf(
        "%s: %d kill points over %.0f us runs: %d kept the earlier output, %d replaced "
        "it, %d absent (none before), %d finished first, %d left temporaries\n",
        out.c_str(), points_, run_us, kept, replaced, absent, finished, left_temps);
    EXPECT_GT(kept, 0) << "no kill landed while an earlier output stood";
    EXPECT_GT(left_temps, 0) << "no kill landed while a temporary existed";

    // What the next run must and must not remove: another process's live
    // temporary, a dead process's temporary of another output, a directory
    // and an unrelated file stay; the kills' leftovers go.
    const std::string name = fs::path(out).filename().string();
    const long dead = DeadPid();
    const std::vector<std::string> keep = {
        "." + name + ".tmp-" + std::to_string(long(getpid())) + "-AbC123",
        ".other.exr.tmp-" + std::to_string(dead) + "-AbC123",
        name + ".tmp-" + std::to_string(dead) + "-AbC123", "notes.txt"};
    for (const auto& k : keep) std::ofstream(dir_ + "/" + k) << "x";
    fs::create_directory(dir_ + "/." + name + ".tmp-" + std::to_string(dead) + "-dir123");
    std::ofstream(dir_ + "/." + name + ".tmp-" + std::to_string(dead) + "-XyZ789") << "stale";
    ASSERT_GT(RunToEnd(args), 0);
    for (const auto& k : keep) EXPECT_TRUE(fs::exists(dir_ + "/" + k)) << k << " was removed";
    EXPECT_TRUE(fs::is_directory(dir_ + "/." + name + ".tmp-" + std::to_string(dead) + "-dir123"));
    std::vector<std::string> temps = testing::TempEntries(dir_);
    EXPECT_EQ(temps.size(), 4u) << "stale temporaries of " << name << " left after a full run";
    for (const auto& k : keep) fs::remove(dir_ + "/" + k);
    fs::remove(dir_ + "/." + name + ".tmp-" + std::to_string(dead) + "-dir123");
    EXPECT_TRUE(testing::TempEntries(dir_).empty());
    auto last = read(out);
    ASSERT_TRUE(last.ok());
    EXPECT_EQ(last->pixels, ref->pixels);
  }

  // Sends `sig` (SIGTERM, SIGINT) at points_ / 4 random moments within 1.1
  // run times: the tool ends with 128 + sig (or 0 when it finished first, or
  // by the signal itself when it came before the handler, when no temporary
  // exists yet), removes its temporaries every time, and the output is the
  // earlier file or a complete new one.
  void SignalAtRandomPoints(const std::vector<std::string>& args, const std::string& out,
                            int sig, uint64_t seed) {
    const double run_us = RunToEnd(args);
    ASSERT_GT(run_us, 0) << "the tool failed on its own";
    auto ref = ReadExr(out);
    ASSERT_TRUE(ref.ok()) << ref.status().ToString();
    std::string previous = Slurp(out);
    std::mt19937_64 rng(seed);
    int handled = 0, finished = 0, early = 0;
    const int points = std::max(4, points_ / 4);
    for (int i = 0; i < points; ++i) {
      const auto delay = std::chrono::microseconds(
          int64_t(std::uniform_real_distribution<double>(0.0, 1.1 * run_us)(rng)));
      const pid_t pid = testing::SpawnInGroup(args);
      ASSERT_GT(pid, 0);
      std::this_thread::sleep_for(delay);
      kill(pid, sig);
      int status = 0;
      ASSERT_EQ(waitpid(pid, &status, 0), pid);
      if (WIFEXITED(status) && WEXITSTATUS(status) == 0) {
        ++finished;
      } else if (WIFEXITED(status)) {
        ASSERT_EQ(WEXITSTATUS(status), 128 + sig) << "signal point " << i;
        ++handled;
      } else {
        ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << "signal point " << i;
        ++early;
      }
      ASSERT_EQ(testing::TempEntries(dir_), std::vector<std::string>{})
          << "signal point " << i << " (" << delay.count() << " us) left a temporary";
      ASSERT_TRUE(fs::exists(out)) << "signal point " << i << ": the earlier output vanished";
      const std::string now = Slurp(out);
      if (now == previous) continue;
      auto img = ReadExr(out);
      ASSERT_TRUE(img.ok()) << "signal point " << i << ": a broken output";
      ASSERT_TRUE(img->info.complete);
      ASSERT_EQ(img->pixels, ref->pixels);
      previous = now;
    }
    std::printf("%s: signal %d at %d points over %.0f us runs: %d handled (exit %d), %d finished "
                "first, %d before the handler\n",
                out.c_str(), sig, points, run_us, handled, 128 + sig, finished, early);
    EXPECT_GT(handled, 0) << "no signal landed while the tool ran";
  }

  std::string dir_, store_;
  int points_ = 100;
};

TEST_F(Kill, RenderOverAnEarlierFrame) {
  KillAtRandomPoints(Render(dir_ + "/out.exr"), dir_ + "/out.exr", 11);
}

TEST_F(Kill, RenderOfATilesPartOverAnEarlierPart) {
  const std::string p1 = dir_ + "/p1.exr", p3 = dir_ + "/p3.exr", check = dir_ + "/check";
  ASSERT_GT(RunToEnd(Render(p1, "1/3")), 0);
  ASSERT_GT(RunToEnd(Render(p3, "3/3")), 0);
  fs::create_directory(check);
  auto merged = [&](const std::string& part) -> StatusOr<ExrImage> {
    VOX_RETURN_IF_ERROR(MergeParts({p1, part, p3}, check + "/merged.exr"));
    return ReadExr(check + "/merged.exr");
  };
  KillAtRandomPoints(Render(dir_ + "/part2.exr", "2/3"), dir_ + "/part2.exr", 12, merged);
}

TEST_F(Kill, MergeOverAnEarlierMerge) {
  std::vector<std::string> parts;
  for (int i = 1; i <= 3; ++i) {
    parts.push_back(dir_ + "/p" + std::to_string(i) + ".exr");
    ASSERT_GT(RunToEnd(Render(parts.back(), std::to_string(i) + "/3")), 0);
  }
  const std::string out = dir_ + "/merged.exr";
  std::vector<std::string> args = {VOX_MERGE_BIN};
  args.insert(args.end(), parts.begin(), parts.end());
  args.insert(args.end(), {"-o", out, "--quiet"});
  std::vector<std::string> before;
  for (const auto& p : parts) before.push_back(Slurp(p));
  KillAtRandomPoints(args, out, 13);
  for (size_t i = 0; i < parts.size(); ++i)
    EXPECT_EQ(Slurp(parts[i]), before[i]) << parts[i] << " changed";
}

TEST_F(Kill, RenderStoppedBySigtermAndSigint) {
  SignalAtRandomPoints(Render(dir_ + "/out.exr"), dir_ + "/out.exr", SIGTERM, 21);
  SignalAtRandomPoints(Render(dir_ + "/out.exr"), dir_ + "/out.exr", SIGINT, 22);
}

TEST_F(Kill, MergeStoppedBySigtermAndSigint) {
  std::vector<std::string> parts;
  for (int i = 1; i <= 3; ++i) {
    parts.push_back(dir_ + "/p" + std::to_string(i) + ".exr");
    ASSERT_GT(RunToEnd(Render(parts.back(), std::to_string(i) + "/3")), 0);
  }
  std::vector<std::string> args = {VOX_MERGE_BIN};
  args.insert(args.end(), parts.begin(), parts.end());
  args.insert(args.end(), {"-o", dir_ + "/merged.exr", "--quiet"});
  SignalAtRandomPoints(args, dir_ + "/merged.exr", SIGTERM, 23);
  SignalAtRandomPoints(args, dir_ + "/merged.exr", SIGINT, 24);
}

}  // namespace
}  // namespace vox

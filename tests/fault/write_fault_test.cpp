// Write-side faults injected into the tools by an LD_PRELOAD shim
// (fault_shim.cpp): a full disk (ENOSPC, after 0 bytes and part-way, the
// crossing write cut short), EIO on write and on fsync, a failing rename,
// and short writes everywhere. For the store writer (vox-gen replacing a
// store with --force), vox-render's EXR, PNG and --stats outputs, and
// vox-merge: each failure is a clear error naming the output, the earlier
// output survives byte for byte, and no temporary is left. Short writes
// alone change nothing: the tools finish and their outputs are complete.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "render/exr.h"
#include "render/tiles.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/common/run_command.h"
#include "tests/common/spawn.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

using Result = testing::CommandResult;

Result RunTool(const std::string& env, const std::string& cmd) {
  // Under ASan the shim cannot come first in the library order: allow it.
  return testing::RunCommand("ASAN_OPTIONS=verify_asan_link_order=0:detect_leaks=0 " + env + " " + cmd);
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::string Shim(const std::string& mode, const std::string& path, const std::string& err,
                 uint64_t after = 0) {
  return "LD_PRELOAD=" + std::string(VOX_FAULT_SHIM) + " VOX_FAULT=" + mode +
         " VOX_FAULT_PATH=" + path + " VOX_FAULT_ERRNO=" + err +
         " VOX_FAULT_AFTER=" + std::to_string(after);
}

struct Fault {
  std::string mode, err;
  uint64_t after;
  std::string words;  // in the tool's message
};

const std::vector<Fault> kFaults = {
    {"write", "ENOSPC", 0, "No space left on device"},
    {"write", "ENOSPC", 20000, "No space left on device"},
    {"write", "EIO", 3000, "Input/output error"},
    {"fsync", "EIO", 0, "Input/output error"},
    {"rename", "EIO", 0, "Input/output error"},
};

class WriteFault : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/vox-fault-XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    store_ = dir_ + "/store";
    ASSERT_EQ(RunTool("", Gen(store_)).code, 0);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Gen(const std::string& out, const std::string& extra = "") {
    return std::string(VOX_GEN_BIN) + " sphere " + out + " --size 64 --quiet " + extra;
  }
  std::string Render(const std::string& args) {
    return std::string(VOX_RENDER_BIN) + " " + store_ + " --size 96x64 --tile-size 16 --quiet " +
           "--threads 2 " + args;
  }
  std::string dir_, store_;
};

TEST_F(WriteFault, StoreWriterKeepsTheEarlierStore) {
  auto before = Store::Open(store_, {});
  ASSERT_TRUE(before.ok());
  const uint64_t id = (*before)->store_id();
  const uint64_t voxels = (*before)->meta().voxel_count;
  before->reset();
  for (const Fault& f : kFaults) {
    const std::string path = f.mode == "rename" ? ".store.tmp-" : "/.store.tmp-";
    Result r = RunTool(Shim(f.mode, path, f.err, f.after), Gen(store_, "--force --size 128"));
    SCOPED_TRACE(f.mode + " " + f.err + " after " + std::to_string(f.after) + ": " + r.output);
    EXPECT_NE(r.output.find("fault_shim: injected"), std::string::npos) << "fault not reached";
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.output.find(f.words), std::string::npos);
    EXPECT_NE(r.output.find(store_), std::string::npos) << "the message names the store";
    auto after = Store::Open(store_, {});
    ASSERT_TRUE(after.ok()) << after.status().ToString();
    EXPECT_EQ((*after)->store_id(), id) << "the earlier store is untouched";
    EXPECT_TRUE(testing::TempEntries(dir_).empty());
  }
  // A new store that fails leaves nothing at its path.
  Result r = RunTool(Shim("write", "/.fresh.tmp-", "ENOSPC", 5000), Gen(dir_ + "/fresh"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_FALSE(fs::exists(dir_ + "/fresh"));
  EXPECT_TRUE(testing::TempEntries(dir_).empty());
  // Short writes: a complete, identical store.
  r = RunTool(Shim("short", "/.short.tmp-", "EIO"), Gen(dir_ + "/short"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto s = Store::Open(dir_ + "/short", {});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->meta().voxel_count, voxels);
  for (uint32_t b = 0; b < (*s)->meta().brick_count; ++b) ASSERT_TRUE((*s)->FetchBrick(b).ok());
}

// Also a regression test for a hang: OpenEXR's TiledOutputFile never
// releases the tile buffer whose write threw, so a second writeTile (another
// render thread's tile) waited forever; TiledExrWriter now refuses every
// write after the first failure.
TEST_F(WriteFault, RenderOutputsKeepTheirEarlierFiles) {
  const std::string exr = dir_ + "/out.exr", png = dir_ + "/out.png", stats = dir_ + "/s.json";
  ASSERT_EQ(RunTool("", Render("-o " + exr + " --preview " + png + " --stats " + stats)).code, 0);
  std::string exr0 = Slurp(exr), png0 = Slurp(png), stats0 = Slurp(stats);
  ASSERT_GT(exr0.size(), 1000u);
  struct Target {
    std::string name, path;
  } targets[] = {{".out.exr.tmp-", exr}, {".s.json.tmp-", stats}, {".out.png.tmp-", png}};
  for (const Target& t : targets)
    for (const Fault& f : kFaults) {
      Result r = RunTool(Shim(f.mode, t.name, f.err, f.after),
                     Render("-o " + exr + " --preview " + png + " --stats " + stats));
      const bool reached = r.output.find("fault_shim: injected") != std::string::npos;
      SCOPED_TRACE(t.name + " " + f.mode + " " + f.err + ": " + r.output);
      if (!reached) {
        // libpng writes through stdio, whose write(2) the shim cannot see;
        // a small output may also end before the fault's byte offset.
        EXPECT_TRUE(t.name == ".out.png.tmp-" || f.after > 0) << "fault not reached";
        EXPECT_EQ(r.code, 0);
        // The run replaced every output: they are the earlier outputs now.
        exr0 = Slurp(exr), png0 = Slurp(png), stats0 = Slurp(stats);
        continue;
      }
      EXPECT_EQ(r.code, 1);
      EXPECT_NE(r.output.find(f.words), std::string::npos);
      EXPECT_NE(r.output.find(t.path), std::string::npos) << "the message names the output";
      EXPECT_EQ(Slurp(t.path), t.path == exr ? exr0 : t.path == png ? png0 : stats0)
          << "the earlier output is untouched";
      EXPECT_TRUE(testing::TempEntries(dir_).empty());
    }
  // Short writes on the EXR: it completes and has the same size (the
  // timings in its header differ, their slot does not).
  Result r = RunTool(Shim("short", ".out.exr.tmp-", "EIO"), Render("-o " + exr));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(Slurp(exr).size(), exr0.size());
}

TEST_F(WriteFault, MergeKeepsTheEarlierImage) {
  const std::string p1 = dir_ + "/p1.exr", p2 = dir_ + "/p2.exr", out = dir_ + "/merged.exr";
  ASSERT_EQ(RunTool("", Render("-o " + p1 + " --tiles 1/2")).code, 0);
  ASSERT_EQ(RunTool("", Render("-o " + p2 + " --tiles 2/2")).code, 0);
  const std::string merge = std::string(VOX_MERGE_BIN) + " " + p1 + " " + p2 + " -o " + out +
                            " --quiet";
  ASSERT_EQ(RunTool("", merge).code, 0);
  const std::string out0 = Slurp(out), p10 = Slurp(p1);
  ASSERT_GT(out0.size(), 4000u);
  for (Fault f : kFaults) {
    // The merged image is smaller than a part: the part-way faults strike
    // inside it.
    if (f.after > 0) f.after = std::min<uint64_t>(f.after, out0.size() / 2);
    Result r = RunTool(Shim(f.mode, ".merged.exr.tmp-", f.err, f.after), merge);
    SCOPED_TRACE(f.mode + " " + f.err + ": " + r.output);
    ASSERT_NE(r.output.find("fault_shim: injected"), std::string::npos) << "fault not reached";
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.output.find(f.words), std::string::npos);
    EXPECT_NE(r.output.find(out), std::string::npos);
    EXPECT_EQ(Slurp(out), out0);
    EXPECT_EQ(Slurp(p1), p10);
    EXPECT_TRUE(testing::TempEntries(dir_).empty());
  }
  Result r = RunTool(Shim("short", ".merged.exr.tmp-", "EIO"), merge);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(Slurp(out), out0) << "merging is deterministic";
}

// The writer itself, without the shim: a file size limit (RLIMIT_FSIZE, so
// writes past it fail with EFBIG) makes one tile's write fail part-way.
// OpenEXR's TiledOutputFile never releases the tile buffer whose write
// threw, so a second writeTile would wait for it forever: every later
// WriteTile must return the first error at once, and Finish must fail and
// leave no temporary. Runs in a child with a watchdog (a hang is SIGALRM).
TEST(TiledExrWriterFault, WritesAfterAFailureFailAtOnce) {
  char tmpl[] = "/tmp/vox-fault-XXXXXX";
  ASSERT_NE(mkdtemp(tmpl), nullptr);
  const std::string dir = tmpl, path = dir + "/out.exr";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    alarm(30);
    signal(SIGXFSZ, SIG_IGN);
    struct rlimit lim = {8000, 8000};
    if (setrlimit(RLIMIT_FSIZE, &lim) != 0) _exit(10);
    ImageLayers layers;
    auto w = TiledExrWriter::Create(path, 64, 64, 16, layers, {}, ExrCompression::kNone);
    if (!w.ok()) _exit(11);
    const TileLayout layout(64, 64, 16);
    TileBuffer buf;
    buf.Allocate(16, layers);
    Status first;
    size_t i = 0;
    for (; i < layout.order().size() && first.ok(); ++i) {
      for (auto& c : buf.ch) std::fill(c.begin(), c.end(), float(i) / 16.0f);
      first = (*w)->WriteTile(layout.order()[i], buf);
    }
    if (first.ok()) _exit(12);  // the limit was never reached
    if (first.ToString().find(path) == std::string::npos) _exit(13);
    for (; i < layout.order().size(); ++i)  // hangs here without the fix
      if ((*w)->WriteTile(layout.order()[i], buf).ToString() != first.ToString()) _exit(14);
    if ((*w)->Close().ok()) _exit(15);
    if (!fs::is_empty(dir)) _exit(16);  // no output, no temporary
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  fs::remove_all(dir);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status)
                                 << (WTERMSIG(status) == SIGALRM ? " (hung)" : "");
  EXPECT_EQ(WEXITSTATUS(status), 0)
      << "10 setrlimit, 11 create, 12 no failure, 13 message lacks the path, 14 a later "
         "tile did not return the first error, 15 Close succeeded, 16 something left behind";
}

}  // namespace
}  // namespace vox

// "Nothing a user owns is ever overwritten", end to end through
// vox-render, vox-merge and vox-info: an output naming an input (a store
// file, the camera, the scene, a part, through a symlink or a hard link) or
// another output is refused before any work, naming both; the format
// follows the extension; empty paths are refused; the outputs of a run are
// published together (a failing --stats keeps the earlier EXR); a FIFO in
// place of a store file is refused, not waited on; huge frames need
// --allow-huge; oversized camera files are refused before reading; and
// vox-render and vox-merge stop on SIGTERM, SIGINT and SIGHUP with 128 + the
// signal, their temporaries removed and the earlier outputs kept.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "tests/common/run_command.h"
#include "tests/common/spawn.h"
#include "tests/render/store_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using testing::RunCommand;

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

bool Has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

class UserPathsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_user_paths_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    ASSERT_TRUE(testing::WriteSphereShellStore(Path("store")).ok());
    std::ofstream(Path("cam.json")) << R"({"position":[0,3,20], "look_at":[0,0,0], "up":[0,1,0],
                                         "fov_deg":40, "width":48, "height":32})";
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string Render(const std::string& args, const std::string& cam = "cam.json") {
    return std::string(VOX_RENDER_BIN) + " " + Path("store") + " --cam " + Path(cam) +
           " --quiet --tile-size 16 " + args;
  }
  static std::vector<std::string> Temporaries() {
    std::vector<std::string> v;
    for (const auto& e : fs::recursive_directory_iterator(*dir_))
      if (Has(e.path().filename().string(), ".tmp-")) v.push_back(e.path().string());
    return v;
  }
  // The store's files, byte for byte.
  static std::string StoreBytes() {
    return Bytes(Path("store/index.vxi")) + Bytes(Path("store/bricks.vxb"));
  }
  static fs::path* dir_;
};
fs::path* UserPathsTest::dir_ = nullptr;

TEST_F(UserPathsTest, AnOutputNeverReplacesAStoreFileCameraOrScene) {
  const std::string store = StoreBytes(), cam = Bytes(Path("cam.json"));
  fs::create_symlink(Path("store/index.vxi"), Path("index-link.exr"));
  fs::create_hard_link(Path("store/bricks.vxb"), Path("bricks-link.exr"));
  fs::copy_file(Path("cam.json"), Path("view.exr"));
  std::ofstream(Path("scene.png")) << R"({"max_depth": 2})";
  const std::string scene = Bytes(Path("scene.png"));
  struct Case {
    std::string args, first, second;
  };
  for (const Case& c : std::vector<Case>{
           {"-o " + Path("store/index.vxi"), "store/index.vxi", ".exr"},
           {"-o " + Path("index-link.exr"), "index-link.exr", "store/index.vxi"},
           {"-o " + Path("bricks-link.exr"), "bricks-link.exr", "store/bricks.vxb"},
           {"-o " + Path("x.exr") + " --stats " + Path("store/index.vxi"), "--stats", "index.vxi"},
           {"-o " + Path("x.exr") + " --preview " + Path("scene.png") + " --scene " +
                Path("scene.png"),
            "--preview", "scene"}}) {
    const testing::CommandResult r = RunCommand(Render(c.args));
    EXPECT_EQ(r.code, 1) << c.args << ": " << r.output;
    EXPECT_TRUE(Has(r.output, c.first) && Has(r.output, c.second)) << c.args << ": " << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  }
  // The camera itself as the output (its name ends in .exr).
  std::string view = Bytes(Path("view.exr"));
  testing::CommandResult r = RunCommand(std::string(VOX_RENDER_BIN) + " " + Path("store") +
                                        " --cam " + Path("view.exr") + " -o " + Path("view.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "-o " + Path("view.exr") + " is the camera")) << r.output;
  EXPECT_EQ(Bytes(Path("view.exr")), view);
  EXPECT_EQ(StoreBytes(), store);
  EXPECT_EQ(Bytes(Path("cam.json")), cam);
  EXPECT_EQ(Bytes(Path("scene.png")), scene);
  EXPECT_FALSE(fs::exists(Path("x.exr")));
  EXPECT_EQ(Temporaries(), std::vector<std::string>{});
}

TEST_F(UserPathsTest, TwoOutputsNeverNameOneFile) {
  // -o a.exr --stats a.exr, and a preview that is a link to the EXR; the
  // second spelling of a file not yet written (./b.exr) too.
  testing::CommandResult r = RunCommand(Render("-o " + Path("a.exr") + " --stats " + Path("a.exr")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "are the same file")) << r.output;
  r = RunCommand("cd " + dir_->string() + " && " +
                 Render("-o b.exr --stats ./b.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_FALSE(fs::exists(Path("b.exr")));
  ASSERT_EQ(RunCommand(Render("-o " + Path("a.exr"))).code, 0);
  const std::string a = Bytes(Path("a.exr"));
  fs::create_symlink(Path("a.exr"), Path("a.png"));
  r = RunCommand(Render("-o " + Path("a.exr") + " --preview " + Path("a.png")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "--preview") && Has(r.output, "-o ")) << r.output;
  EXPECT_EQ(Bytes(Path("a.exr")), a);
}

TEST_F(UserPathsTest, FormatFollowsTheExtensionAndEmptyPathsAreRefused) {
  // A wrong extension fails the run (1); an empty value is a bad flag (2).
  for (const auto& [args, code] :
       {std::pair<std::string, int>{"-o " + Path("x.png"), 1},
        {"-o " + Path("y.exr") + " --preview " + Path("p.jpg"), 1},
        {std::string("-o ''"), 2},
        {"-o " + Path("y.exr") + " --stats ''", 2}}) {
    const testing::CommandResult r = RunCommand(Render(args));
    EXPECT_EQ(r.code, code) << args << ": " << r.output;
    EXPECT_TRUE(Has(r.output, ".exr") || Has(r.output, ".png") || Has(r.output, "empty path") ||
                Has(r.output, "an empty value"))
        << args << ": " << r.output;
  }
  EXPECT_FALSE(fs::exists(Path("x.png")));
  EXPECT_FALSE(fs::exists(Path("y.exr")));
  EXPECT_FALSE(fs::exists(Path("p.jpg")));
  // Upper case is the same format.
  EXPECT_EQ(RunCommand(Render("-o " + Path("UP.EXR"))).code, 0);
}

TEST_F(UserPathsTest, MergeNeverReplacesAPartOrAStoreFile) {
  for (int i = 1; i <= 2; ++i)
    ASSERT_EQ(RunCommand(Render("-o " + Path("p" + std::to_string(i) + ".exr") + " --tiles " +
                                std::to_string(i) + "/2"))
                  .code,
              0);
  const std::string store = StoreBytes(), p2 = Bytes(Path("p2.exr"));
  const std::string parts = Path("p1.exr") + " " + Path("p2.exr");
  fs::create_symlink(Path("p2.exr"), Path("p2-preview.png"));
  for (const std::string& out :
       {" -o " + Path("store/bricks.vxb"), " -o " + Path("p2.exr"),
        " -o " + Path("m.exr") + " --preview " + Path("p2-preview.png")}) {
    const testing::CommandResult r = RunCommand(std::string(VOX_MERGE_BIN) + " " + parts + out);
    EXPECT_EQ(r.code, 1) << out << ": " << r.output;
  }
  EXPECT_EQ(StoreBytes(), store);
  EXPECT_EQ(Bytes(Path("p2.exr")), p2);
  EXPECT_FALSE(fs::exists(Path("m.exr")));
  // A good merge with its preview, published together.
  const testing::CommandResult r = RunCommand(std::string(VOX_MERGE_BIN) + " " + parts + " -o " +
                                              Path("m.exr") + " --preview " + Path("m.png"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(Path("m.exr")) && fs::exists(Path("m.png")));
}

TEST_F(UserPathsTest, OutputsArePublishedTogether) {
  ASSERT_EQ(RunCommand(Render("-o " + Path("d.exr"))).code, 0);
  const std::string d = Bytes(Path("d.exr"));
  if (access("/dev/full", W_OK) != 0) GTEST_SKIP() << "no writable /dev/full";
  const testing::CommandResult r =
      RunCommand(Render("--size 64x64 -o " + Path("d.exr") + " --stats /dev/full"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "/dev/full")) << r.output;
  EXPECT_EQ(Bytes(Path("d.exr")), d) << "the EXR was published although --stats failed";
  EXPECT_EQ(Temporaries(), std::vector<std::string>{});
}

TEST_F(UserPathsTest, AFifoInPlaceOfAStoreFileIsRefusedNotWaitedOn) {
  fs::copy(Path("store"), Path("fifo-store"), fs::copy_options::recursive);
  fs::remove(Path("fifo-store/bricks.vxb"));
  ASSERT_EQ(mkfifo(Path("fifo-store/bricks.vxb").c_str(), 0644), 0);
  for (const std::string& cmd :
       {std::string(VOX_RENDER_BIN) + " " + Path("fifo-store") + " -o " + Path("f.exr"),
        std::string(VOX_INFO_BIN) + " " + Path("fifo-store")}) {
    const auto t0 = std::chrono::steady_clock::now();
    const testing::CommandResult r = RunCommand("timeout 30 " + cmd);
    EXPECT_EQ(r.code, 1) << cmd << ": " << r.output;
    EXPECT_TRUE(Has(r.output, "a FIFO")) << r.output;
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  }
}

TEST_F(UserPathsTest, AFifoGivenAsAMergePartIsRefusedNotWaitedOn) {
  ASSERT_EQ(RunCommand(Render("-o " + Path("q1.exr") + " --tiles 1/2")).code, 0);
  ASSERT_EQ(mkfifo(Path("q2.exr").c_str(), 0644), 0);
  const auto t0 = std::chrono::steady_clock::now();
  const testing::CommandResult r = RunCommand("timeout 30 " + std::string(VOX_MERGE_BIN) + " " +
                                              Path("q1.exr") + " " + Path("q2.exr") + " -o " +
                                              Path("q.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "a FIFO") && Has(r.output, "q2.exr")) << r.output;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));
  EXPECT_FALSE(fs::exists(Path("q.exr")));
}

TEST_F(UserPathsTest, HugeFramesNeedAllowHugeAndOversizedCamerasAreRefused) {
  testing::CommandResult r = RunCommand(
      std::string(VOX_RENDER_BIN) + " " + Path("store") + " --size 100000x100000 -o " +
      Path("huge.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "--allow-huge")) << r.output;
  // Allowed, it still must fit the disk: the estimate is printed and checked.
  r = RunCommand(std::string(VOX_RENDER_BIN) + " " + Path("store") +
                 " --size 1000000x1000000 --allow-huge --tile-size 4096 --layers normal,voxel -o " +
                 Path("huge.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "MiB free") && Has(r.output, "at most")) << r.output;
  EXPECT_FALSE(fs::exists(Path("huge.exr")));
  EXPECT_EQ(Temporaries(), std::vector<std::string>{});
  // A camera file over 16 MiB is refused by its size, before it is read.
  {
    std::ofstream big(Path("big.json"));
    big << "{\"width\": 8, \"pad\": \"" << std::string(17u << 20, 'x') << "\"}";
  }
  r = RunCommand(Render("-o " + Path("c.exr"), "big.json"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "16 MiB")) << r.output;
}

// vox-render and vox-merge stopped by SIGTERM, SIGINT and SIGHUP while
// writing: exit 128 + the signal, no temporary left, the earlier output kept.
TEST_F(UserPathsTest, SignalsStopRenderAndMergeCleanly) {
  ASSERT_EQ(RunCommand(Render("-o " + Path("s.exr"))).code, 0);
  const std::string earlier = Bytes(Path("s.exr"));
  for (int sig : {SIGTERM, SIGINT, SIGHUP}) {
    const pid_t pid = testing::SpawnInGroup(
        {VOX_RENDER_BIN, Path("store"), "--size", "3000x3000", "--threads", "1", "--quiet",
         "--tile-size", "64", "-o", Path("s.exr"), "--stats", Path("s.json")});
    ASSERT_GT(pid, 0);
    // Wait for the EXR's temporary: the render is under way.
    bool started = false;
    for (int i = 0; i < 2000 && !started; ++i) {
      started = !Temporaries().empty();
      if (!started) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    EXPECT_TRUE(started) << "no temporary appeared";
    kill(pid, sig);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status)) << "signal " << sig << " killed it outright";
    EXPECT_EQ(WEXITSTATUS(status), 128 + sig);
    EXPECT_EQ(Temporaries(), std::vector<std::string>{}) << "signal " << sig;
    EXPECT_EQ(Bytes(Path("s.exr")), earlier) << "signal " << sig;
    EXPECT_FALSE(fs::exists(Path("s.json")));
  }
}

}  // namespace
}  // namespace vox

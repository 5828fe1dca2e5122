// Outputs are never half-written and hostile-but-valid input gets clear
// errors: a failed render or merge keeps the earlier output and leaves no
// temporary file, output paths are checked before any work, vox-merge
// refuses an output that is one of its parts and parts of different stores,
// large headers (many lights) keep their timings, absurd image sizes and far
// cameras are refused with the limit named.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "render/camera.h"
#include "render/exr.h"
#include "tests/common/run_command.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

using RunResult = testing::CommandResult;

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

bool Has(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

class OutputSafetyTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("vox_output_safety_test_" + std::to_string(getpid())));
    fs::create_directories(*dir_);
    ASSERT_TRUE(WriteSphere(Path("store")).ok());
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static Status WriteSphere(const std::string& path) { return testing::WriteSphereShellStore(path); }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(Path(name)) << text;
    return Path(name);
  }
  static std::string Render(const std::string& store, const std::string& args) {
    return std::string(VOX_RENDER_BIN) + " " + Path(store) + " " + args;
  }
  static std::string Merge(const std::string& args) {
    return std::string(VOX_MERGE_BIN) + " " + args;
  }
  // Entries of the test directory that look like temporary outputs.
  static std::vector<std::string> Temporaries() {
    std::vector<std::string> v;
    for (const auto& e : fs::directory_iterator(*dir_))
      if (Has(e.path().filename().string(), ".tmp-")) v.push_back(e.path().filename().string());
    return v;
  }
  static std::string Cam() {
    return Write("cam.json",
                 R"({"position":[0,3,20], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40,
                     "width":48, "height":32})");
  }

  static fs::path* dir_;
};
fs::path* OutputSafetyTest::dir_ = nullptr;

TEST_F(OutputSafetyTest, AFailedRenderKeepsTheEarlierOutputs) {
  const std::string cam = Cam();
  const std::string outs = " -o " + Path("out.exr") + " --preview " + Path("out.png") +
                           " --stats " + Path("out.json") + " --quiet --tile-size 16";
  ASSERT_EQ(testing::RunCommand(Render("store", "--cam " + cam + outs)).code, 0);
  const std::string exr = Bytes(Path("out.exr")), png = Bytes(Path("out.png")),
                    json = Bytes(Path("out.json"));
  ASSERT_FALSE(exr.empty() || png.empty() || json.empty());
  // A copy of the store whose brick records are all garbage (sizes intact).
  fs::copy(Path("store"), Path("bad"), fs::copy_options::recursive);
  {
    const auto size = fs::file_size(Path("bad/bricks.vxb"));
    std::fstream f(Path("bad/bricks.vxb"), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(32);
    std::string junk(size_t(size) - 32, '\x5a');
    f.write(junk.data(), std::streamsize(junk.size()));
  }
  RunResult r = testing::RunCommand(Render("bad", "--cam " + cam + outs));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "bricks.vxb") || Has(r.output, "brick")) << r.output;
  EXPECT_EQ(Bytes(Path("out.exr")), exr);
  EXPECT_EQ(Bytes(Path("out.png")), png);
  EXPECT_EQ(Bytes(Path("out.json")), json);
  EXPECT_EQ(Temporaries(), std::vector<std::string>{});
  auto info = ReadExrInfo(Path("out.exr"));
  ASSERT_TRUE(info.ok());
  EXPECT_TRUE(info->complete);
}

TEST_F(OutputSafetyTest, OutputPathsAreCheckedBeforeRendering) {
  const std::string cam = Cam();
  for (const std::string& bad :
       std::vector<std::string>{" --stats /missing-dir/s.json", " --preview /missing-dir/p.png",
                                " --stats " + Path("out-is-a-dir")}) {
    fs::create_directories(Path("out-is-a-dir"));
    RunResult r = testing::RunCommand(Render("store", "--cam " + cam + " -o " + Path("never.exr") + bad));
    EXPECT_EQ(r.code, 1) << bad << ": " << r.output;
    EXPECT_TRUE(Has(r.output, "missing-dir") || Has(r.output, "out-is-a-dir")) << r.output;
    EXPECT_FALSE(Has(r.output, "tiles")) << "rendered before failing: " << r.output;
    EXPECT_FALSE(fs::exists(Path("never.exr")));
  }
  RunResult r = testing::RunCommand(Render("store", "--cam " + cam + " -o /missing-dir/x.exr --quiet"));
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(Has(r.output, "/missing-dir") && Has(r.output, "does not exist")) << r.output;
}

TEST_F(OutputSafetyTest, MergeRefusesAnOutputThatIsAPartAndKeepsEarlierOutputs) {
  const std::string cam = Cam();
  for (int i = 1; i <= 2; ++i)
    ASSERT_EQ(
        testing::RunCommand(Render("store", "--cam " + cam + " -o " + Path("p" + std::to_string(i) + ".exr") +
                                 " --quiet --tile-size 16 --tiles " + std::to_string(i) + "/2"))
            .code,
        0);
  const std::string p1 = Bytes(Path("p1.exr"));
  // The same file under another spelling, and a hard link to it.
  RunResult r = testing::RunCommand("cd " + dir_->string() + " && " + Merge("./p1.exr p2.exr -o p1.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "p1.exr")) << r.output;
  fs::create_hard_link(Path("p1.exr"), Path("link.exr"));
  r = testing::RunCommand(Merge(Path("p1.exr") + " " + Path("p2.exr") + " -o " + Path("link.exr")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_EQ(Bytes(Path("p1.exr")), p1);
  // A good merge, then a failing one (part 2 missing) onto the same output.
  ASSERT_EQ(testing::RunCommand(Merge(Path("p1.exr") + " " + Path("p2.exr") + " -o " + Path("m.exr"))).code, 0);
  const std::string merged = Bytes(Path("m.exr"));
  r = testing::RunCommand(Merge(Path("p1.exr") + " -o " + Path("m.exr")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_EQ(Bytes(Path("m.exr")), merged);
  r = testing::RunCommand(Merge(Path("p1.exr") + " " + Path("p2.exr") + " -o " + Path("m2.exr") +
                 " --preview /missing-dir/m.png"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_FALSE(fs::exists(Path("m2.exr")));
  EXPECT_EQ(Temporaries(), std::vector<std::string>{});
}

TEST_F(OutputSafetyTest, MergeRefusesPartsOfDifferentStores) {
  const std::string cam = Cam();
  ASSERT_TRUE(WriteSphere(Path("s2")).ok());
  auto part = [&](int i) {
    return testing::RunCommand(Render("s2", "--cam " + cam + " -o " + Path("q" + std::to_string(i) + ".exr") +
                                 " --quiet --tile-size 16 --tiles " + std::to_string(i) + "/2"))
        .code;
  };
  ASSERT_EQ(part(1), 0);
  {
    auto store = Store::Open(Path("s2"), {});
    ASSERT_TRUE(store.ok());
    char id[17];
    snprintf(id, sizeof id, "%016llx", (unsigned long long)(*store)->store_id());
    auto info = ReadExrInfo(Path("q1.exr"));
    ASSERT_TRUE(info.ok());
    EXPECT_EQ(info->attrs["vox:storeId"], id);
  }
  ASSERT_TRUE(WriteSphere(Path("s2")).ok());  // re-ingested at the same path: same content
  ASSERT_EQ(part(2), 0);
  RunResult r = testing::RunCommand(Merge(Path("q1.exr") + " " + Path("q2.exr") + " -o " + Path("q.exr")));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "q1.exr") && Has(r.output, "q2.exr") &&
              Has(r.output, "different stores"))
      << r.output;
  EXPECT_FALSE(fs::exists(Path("q.exr")));
}

TEST_F(OutputSafetyTest, TwelveThousandLightsKeepTheirTimings) {
  std::string scene = R"({"lights":[)";
  for (int i = 0; i < 12000; ++i)
    scene += std::string(i ? "," : "") + R"({"type":"point","position":[)" + std::to_string(i % 7) +
             ",9," + std::to_string(i % 11) + R"(],"intensity":0.0001,"shadows":false})";
  scene += "]}";
  Write("lights.json", scene);
  RunResult r = testing::RunCommand(Render("store", "--cam " + Write("small.json", R"({"position":[0,3,20],
      "look_at":[0,0,0], "fov_deg":40, "width":8, "height":8})") +
                                         " --scene " + Path("lights.json") + " -o " +
                                         Path("lights.exr") + " --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto info = ReadExrInfo(Path("lights.exr"));
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_GT(info->attrs["vox:scene"].size(), size_t(1) << 20);
  EXPECT_GT(info->render_seconds, 0.0);
  auto timings = nlohmann::json::parse(info->attrs["vox:timings"]);
  EXPECT_TRUE(timings.contains("render_seconds")) << info->attrs["vox:timings"];
}

TEST(ExrHeader, TimingsArePatchedBehindAHugeAttribute) {
  const std::string path =
      (fs::temp_directory_path() / ("vox_exr_header_" + std::to_string(getpid()) + ".exr"))
          .string();
  ExrAttributes attrs{{"vox:aaa", std::string(3 << 20, 'a')}, {"vox:zzz", "after"}};
  auto w = TiledExrWriter::Create(path, 20, 10, 16, {}, attrs);
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  TileBuffer buf;
  buf.Allocate(16, {});
  TileLayout layout(20, 10, 16);
  for (const TileRect& t : layout.order()) ASSERT_TRUE((*w)->WriteTile(t, buf).ok());
  EXPECT_FALSE(fs::exists(path));  // written beside it until finished
  ASSERT_TRUE((*w)->Finish(2.5, R"({"render_seconds":2.5})").ok());
  auto info = ReadExrInfo(path);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->render_seconds, 2.5);
  EXPECT_EQ(info->attrs["vox:timings"].substr(0, 22), R"({"render_seconds":2.5})");
  EXPECT_EQ(info->attrs["vox:zzz"], "after");
  // An abandoned writer leaves the earlier file as it was.
  const std::string before = Bytes(path);
  {
    auto w2 = TiledExrWriter::Create(path, 20, 10, 16, {}, {});
    ASSERT_TRUE(w2.ok());
    ASSERT_TRUE((*w2)->WriteTile(layout.order()[0], buf).ok());
  }
  EXPECT_EQ(Bytes(path), before);
  fs::remove(path);
}

TEST_F(OutputSafetyTest, AbsurdImageSizesAreRefusedWithTheLimit) {
  RunResult r = testing::RunCommand(Render("store", "--size 1048576x1048576 -o " + Path("huge.exr") + " --quiet"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "tiles") && Has(r.output, std::to_string(kMaxTiles))) << r.output;
  EXPECT_FALSE(fs::exists(Path("huge.exr")));
  EXPECT_EQ(CheckTileCount(131072, 131072, 64).ok(), true);
  EXPECT_EQ(CheckTileCount(131073, 131072, 64).ok(), false);
}

TEST_F(OutputSafetyTest, FarCamerasAreRefusedNearOnesRender) {
  auto cam = [&](double z) {
    return Write("ortho.json", R"({"position":[0.3,0.2,)" + std::to_string(z) +
                                   R"(], "look_at":[0.3,0.2,0], "projection":"orthographic",
                                   "ortho_width":14, "width":16, "height":16})");
  };
  RunResult r = testing::RunCommand(Render("store", "--cam " + cam(20) + " -o " + Path("near.exr") + " --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto img = ReadExr(Path("near.exr"));
  ASSERT_TRUE(img.ok());
  EXPECT_EQ(img->pixels["A"][8 * 16 + 8], 1.0f);
  for (double z : {1e17, 1e30, 1e300}) {
    r = testing::RunCommand(Render("store", "--cam " + cam(z) + " -o " + Path("far.exr") + " --quiet"));
    EXPECT_EQ(r.code, 1) << z << ": " << r.output;
    EXPECT_TRUE(Has(r.output, "camera position") && Has(r.output, "65536")) << r.output;
    EXPECT_FALSE(fs::exists(Path("far.exr")));
  }
}

}  // namespace
}  // namespace vox

namespace vox {
namespace {

// SIGPIPE (an output or the log piped to a reader that is gone, `| head`)
// fails the write like any other: the run exits 1, publishes nothing and
// leaves no temporary, where it used to die with the EXR's behind.
TEST_F(OutputSafetyTest, ABrokenPipeLeavesNoTemporaries) {
  const std::string cmd = Render("store", "--size 16x16 --tile-size 16 --quiet -o " +
                                              Path("pipe.exr") + " --stats /dev/stdout 2>" +
                                              Path("pipe.err"));
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  close(fds[0]);  // the reader is gone before the first byte
  const pid_t pid = fork();
  if (pid == 0) {
    signal(SIGPIPE, SIG_DFL);
    dup2(fds[1], 1);
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  close(fds[1]);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  const std::string err = Bytes(Path("pipe.err"));
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1)
      << "status " << status << (WIFSIGNALED(status) ? " (signal)" : "") << ": " << err;
  EXPECT_TRUE(Has(err, "/dev/stdout")) << err;
  EXPECT_FALSE(fs::exists(Path("pipe.exr")));
  for (const auto& e : fs::directory_iterator(*dir_))
    EXPECT_EQ(e.path().filename().string().find(".pipe.exr.tmp-"), std::string::npos)
        << e.path();
}

}  // namespace
}  // namespace vox

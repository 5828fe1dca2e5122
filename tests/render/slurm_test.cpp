// The example Slurm job arrays (scripts/slurm/submit.sh) end to end on a
// one-node cluster: start it with the shared slurm-single-node tool, render
// a frame in 3 array tasks plus a dependent merge (sbatch --wait), check the
// merged EXR equals a direct render bit for bit, stop the cluster; and a
// turntable's frames in chunks (submit.sh --frames), each frame equal to the
// one process's. Skipped when the tool is absent. Labelled long;slurm.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "render/exr.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

int Sh(const std::string& cmd) {
  int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string SlurmTool() {
  const char* env = std::getenv("VOX_SLURM_TOOL");
  // Default: the workplace's shared tools beside the repository.
  return env ? env : VOX_SLURM_TOOL_DEFAULT;
}

// Stops the cluster however the test ends.
struct Cluster {
  std::string tool;
  bool started = false;
  ~Cluster() {
    if (started) Sh(tool + " stop");
  }
};

TEST(SlurmTest, JobArrayRendersAndMergesOneFrame) {
  const std::string tool = SlurmTool();
  if (access(tool.c_str(), X_OK) != 0) GTEST_SKIP() << tool << " not available";
  fs::path dir = fs::temp_directory_path() / ("vox_slurm_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  StoreMeta meta = testing::TestMeta(6, GridClass::kLevelSet, 0.1);
  meta.brick_level = 3;
  std::vector<MemoryVoxel> voxels = testing::ShellVoxels(64, glm::dvec3(31.5), 22, 25);
  const std::string store = (dir / "store").string();
  ASSERT_TRUE(testing::WriteStore(store, meta, voxels).ok());
  const std::string cam = (dir / "cam.json").string();
  std::ofstream(cam)
      << R"({"position":[3.2,5,9], "look_at":[3.2,3.2,3.2], "fov_deg":40, "width":96, "height":72})";
  const std::string render = VOX_RENDER_BIN, merge = VOX_MERGE_BIN;
  ASSERT_EQ(Sh(render + " " + store + " --cam " + cam + " -o " + (dir / "full.exr").string() +
               " --tile-size 16 --quiet"),
            0);

  Cluster cluster{tool};
  ASSERT_EQ(Sh(tool + " start"), 0) << "could not start the one-node cluster";
  cluster.started = true;
  const std::string out = (dir / "split.exr").string();
  int rc = Sh("VOX_RENDER=" + render + " VOX_MERGE=" + merge + " " + VOX_SLURM_SUBMIT +
              " --wait --preview " + (dir / "split.png").string() + " " + store + " " + cam + " " +
              out + " 3 --tile-size 16");
  ASSERT_EQ(rc, 0) << "see the logs in " << dir / "split.parts";
  for (int i = 1; i <= 3; ++i)
    EXPECT_TRUE(fs::exists(dir / "split.parts" / ("part-" + std::to_string(i) + "-of-3.exr")));
  EXPECT_TRUE(fs::exists(dir / "split.png"));
  auto full = ReadExr((dir / "full.exr").string());
  auto split = ReadExr(out);
  ASSERT_TRUE(full.ok() && split.ok()) << split.status().ToString();
  EXPECT_EQ(split->info.attrs["vox:mergedFrom"], "3 parts");
  for (const auto& [name, pixels] : full->pixels)
    EXPECT_EQ(std::memcmp(pixels.data(), split->pixels[name].data(), pixels.size() * 4), 0) << name;
  fs::remove_all(dir);
}

TEST(SlurmTest, FramesArrayRendersASequenceInChunks) {
  const std::string tool = SlurmTool();
  if (access(tool.c_str(), X_OK) != 0) GTEST_SKIP() << tool << " not available";
  fs::path dir = fs::temp_directory_path() / ("vox_slurm_frames_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  StoreMeta meta = testing::TestMeta(6, GridClass::kLevelSet, 0.1);
  meta.brick_level = 3;
  const std::string store = (dir / "store").string();
  ASSERT_TRUE(testing::WriteStore(store, meta, testing::ShellVoxels(64, glm::dvec3(31.5), 22, 25)).ok());
  const std::string render = VOX_RENDER_BIN;
  const std::string flags = " --turntable 5 --size 48x32 --tile-size 16 --quiet";
  // The whole sequence in one process, for reference.
  ASSERT_EQ(Sh(render + " " + store + " -o " + (dir / "ref.%d.exr").string() + flags), 0);

  Cluster cluster{tool};
  ASSERT_EQ(Sh(tool + " start"), 0) << "could not start the one-node cluster";
  cluster.started = true;
  // 5 frames in chunks of 2: tasks of frames 1-2, 3-4 and 5.
  const int rc = Sh("cd " + dir.string() + " && VOX_RENDER=" + render + " " + VOX_SLURM_SUBMIT +
                    " --frames 5 --chunk 2 --wait " + store + " out/tt.%04d.exr" + flags +
                    " --stats out/tt.%04d.json");
  ASSERT_EQ(rc, 0) << "see the logs in " << dir / "out";
  for (int n = 1; n <= 5; ++n) {
    char name[32];
    snprintf(name, sizeof name, "tt.%04d", n);
    auto frame = ReadExr((dir / "out" / (std::string(name) + ".exr")).string());
    auto ref = ReadExr((dir / ("ref." + std::to_string(n) + ".exr")).string());
    ASSERT_TRUE(frame.ok() && ref.ok()) << name << ": " << frame.status().ToString();
    for (const auto& [channel, pixels] : ref->pixels)
      EXPECT_EQ(std::memcmp(pixels.data(), frame->pixels[channel].data(), pixels.size() * 4), 0)
          << name << " " << channel;
    std::ifstream stats(dir / "out" / (std::string(name) + ".json"));
    std::string text((std::istreambuf_iterator<char>(stats)), std::istreambuf_iterator<char>());
    const int first = (n - 1) / 2 * 2 + 1;
    EXPECT_NE(text.find("\"first\": " + std::to_string(first)), std::string::npos) << name << text;
  }
  EXPECT_FALSE(fs::exists(dir / "out" / "tt.0006.exr"));
  for (int task = 1; task <= 3; ++task)
    EXPECT_TRUE(fs::exists(dir / "out" / ("frames-" + std::to_string(task) + ".log"))) << task;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace vox

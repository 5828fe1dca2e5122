// The example Slurm job array (scripts/slurm/submit.sh) end to end on a
// one-node cluster: start it with the shared slurm-single-node tool, render
// a frame in 3 array tasks plus a dependent merge (sbatch --wait), check the
// merged EXR equals a direct render bit for bit, stop the cluster. Skipped
// when the tool is absent. Labelled long;slurm.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

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
  return env ? env : "/work/shared/tools/slurm-single-node";
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

}  // namespace
}  // namespace vox

// Silhouettes against OpenVDB's vdb_render (long): a level-set sphere and a
// dodecahedron of 1024^3 generated with vdb_tool, ingested with vox-ingest,
// rendered at 1024x1024 by vox-render and by `vdb_render -shader matte` with
// the same camera; the hit masks must agree to >= 99% IoU.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "render/exr.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

int Sh(const std::string& cmd) {
  int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

bool HaveTool(const std::string& name) {
  return Sh("command -v " + name + " >/dev/null 2>&1") == 0;
}

// vdb_render writes a scanline RGBA EXR whose alpha is 1 everywhere; with
// the matte shader a hit pixel is white and the background black.
std::vector<uint8_t> VdbMask(const std::string& path, int* w, int* h) {
  Imf::InputFile in(path.c_str());
  const auto& dw = in.header().dataWindow();
  *w = dw.max.x - dw.min.x + 1;
  *h = dw.max.y - dw.min.y + 1;
  const char* ch = "R";
  std::vector<float> px(size_t(*w) * *h);
  Imf::FrameBuffer fb;
  fb.insert(ch,
            Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(px.data() - dw.min.x - dw.min.y * *w),
                       sizeof(float), sizeof(float) * size_t(*w)));
  in.setFrameBuffer(fb);
  in.readPixels(dw.min.y, dw.max.y);
  std::vector<uint8_t> mask(px.size());
  for (size_t i = 0; i < px.size(); ++i) mask[i] = px[i] > 0.5f;
  return mask;
}

double Iou(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    inter += a[i] && b[i];
    uni += a[i] || b[i];
  }
  return uni ? double(inter) / double(uni) : 1.0;
}

class SilhouetteTest : public ::testing::TestWithParam<std::pair<const char*, const char*>> {};

TEST_P(SilhouetteTest, MatchesVdbRender) {
  if (!HaveTool("vdb_tool") || !HaveTool("vdb_render"))
    GTEST_SKIP() << "vdb_tool/vdb_render not installed";
  const auto [name, make] = GetParam();
  fs::path dir = fs::temp_directory_path() /
                 ("vox_silhouette_" + std::string(name) + "_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string vdb = (dir / "in.vdb").string(), store = (dir / "store").string();
  ASSERT_EQ(Sh(std::string("vdb_tool ") + make + " -write " + vdb + " >/dev/null 2>&1"), 0);
  ASSERT_EQ(Sh(std::string(VOX_INGEST_BIN) + " " + vdb + " " + store + " --quiet --force"), 0);
  const char* pos = "0.9,1.2,3.4";
  std::ofstream(dir / "cam.json")
      << R"({"position":[0.9,1.2,3.4], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40, "width":1024, "height":1024})";
  std::ofstream(dir / "scene.json") << R"({"lights":[]})";
  ASSERT_EQ(Sh(std::string(VOX_RENDER_BIN) + " " + store + " --cam " + (dir / "cam.json").string() +
               " --scene " + (dir / "scene.json").string() + " -o " + (dir / "vox.exr").string() +
               " --quiet"),
            0);
  ASSERT_EQ(
      Sh("vdb_render " + vdb + " " + (dir / "vdb.exr").string() + " -translate " + pos +
         " -lookat 0,0,0 -up 0,1,0 -fov 40 -res 1024x1024 -shader matte -cpus 2 >/dev/null 2>&1"),
      0);
  auto ours = ReadExr((dir / "vox.exr").string());
  ASSERT_TRUE(ours.ok()) << ours.status().ToString();
  int w = 0, h = 0;
  std::vector<uint8_t> theirs = VdbMask((dir / "vdb.exr").string(), &w, &h);
  ASSERT_EQ(w, 1024);
  ASSERT_EQ(h, 1024);
  std::vector<uint8_t> mine(theirs.size());
  size_t hits = 0;
  for (size_t i = 0; i < mine.size(); ++i) hits += mine[i] = ours->pixels["A"][i] > 0.5f;
  double iou = Iou(mine, theirs);
  printf("%s: IoU %.5f (%zu vox hit pixels)\n", name, iou, hits);
  EXPECT_GT(hits, 100000u);
  EXPECT_GE(iou, 0.99);
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, SilhouetteTest,
    ::testing::Values(std::make_pair("sphere", "-sphere d=1024 r=1 c=0,0,0 w=3"),
                      std::make_pair("dodecahedron", "-platonic d=1024 f=12 s=1 w=3")),
    [](const auto& info) { return std::string(info.param.first); });

}  // namespace
}  // namespace vox

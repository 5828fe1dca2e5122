// vox-render and vox-merge end to end on a store written with StoreWriter:
// outputs, --stats, --tiles + vox-merge, and the error exits for bad camera
// and scene files.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "render/camera.h"
#include "render/exr.h"
#include "tests/common/run_command.h"
#include "tests/render/store_suite.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

using RunResult = testing::CommandResult;

class CliTest : public testing::SphereShellStoreSuite {
 protected:
  static std::string Render(const std::string& args) {
    return std::string(VOX_RENDER_BIN) + " " + Path("store") + " " + args;
  }
};

const char kCam[] =
    R"({"position":[0,3,20], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40, "width":64, "height":48, "projection":"perspective"})";

TEST_F(CliTest, RendersExrPreviewAndStats) {
  std::string cam = Write("cam.json", kCam);
  RunResult r =
      testing::RunCommand(Render("--cam " + cam + " -o " + Path("a.exr") + " --preview " + Path("a.png") +
                  " --stats " + Path("a.json") + " --threads 2 --tile-size 16 --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output, "");  // --quiet
  EXPECT_TRUE(fs::exists(Path("a.png")));
  auto img = ReadExr(Path("a.exr"));
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_EQ(img->info.width, 64);
  EXPECT_EQ(img->info.attrs["vox:store"], Path("store"));
  // The sphere (world radius 5 at distance 20) covers the image centre, not the corners.
  EXPECT_EQ(img->pixels["A"][24 * 64 + 32], 1.0f);
  EXPECT_EQ(img->pixels["A"][0], 0.0f);
  // Depth at the centre: from z = 20 to the sphere's front, about 15 (ray slightly tilted).
  EXPECT_NEAR(img->pixels["Z"][24 * 64 + 32], std::sqrt(9.0 + 400.0) - 5.0, 0.3);
  std::ifstream in(Path("a.json"));
  auto stats = nlohmann::json::parse(in);
  EXPECT_EQ(stats["rays"]["primary"], 64 * 48);
  EXPECT_GT(stats["rays"]["shadow"].get<int>(), 0);  // default scene: a shadow-casting key light
  EXPECT_GT(stats["cache"]["bricks_paged_in"].get<int>(), 0);
  // Bricks enter the shared cache once, read by a ray (misses) or ahead of
  // it (prefetched); rays entering a brick their thread's table holds never
  // reach it, so shared look-ups (hits + misses, hits only when the other
  // thread loaded the brick) are far fewer than the bricks rays entered.
  const int shared = stats["cache"]["hits"].get<int>() + stats["cache"]["misses"].get<int>();
  EXPECT_EQ(stats["cache"]["misses"].get<int>() + stats["cache"]["prefetched"].get<int>(),
            stats["cache"]["bricks_paged_in"].get<int>());
  EXPECT_GT(stats["dda"]["brick_fetches"].get<int>(), 2 * shared);
  EXPECT_GT(stats["dda"]["moves"].get<int>(), 0);
  EXPECT_EQ(stats["threads"], 2);
}

TEST_F(CliTest, FloatAndCompressionFlags) {
  std::string cam = Write("cam.json", kCam);
  RunResult r = testing::RunCommand(Render("--cam " + cam + " -o " + Path("h.exr") + " --threads 2 --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  r = testing::RunCommand(Render("--cam " + cam + " -o " + Path("f.exr") +
                  " --float --compression none --threads 2 --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto h = ReadExrInfo(Path("h.exr"));
  auto f = ReadExrInfo(Path("f.exr"));
  ASSERT_TRUE(h.ok() && f.ok());
  EXPECT_FALSE(h->float_color);
  EXPECT_EQ(h->compression, "rle");
  EXPECT_TRUE(f->float_color);
  EXPECT_EQ(f->compression, "none");
  r = testing::RunCommand(Render("--cam " + cam + " -o " + Path("x.exr") + " --compression lzw"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("EXR compression 'lzw': expected zip"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(Path("x.exr")));
}

TEST_F(CliTest, DefaultCameraAndPlainProgress) {
  RunResult r = testing::RunCommand(Render("-o " + Path("d.exr") + " --size 40x30 --single-step --threads 1"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("tiles 1/1"), std::string::npos)
      << r.output;  // plain lines, not a terminal
  auto img = ReadExr(Path("d.exr"));
  ASSERT_TRUE(img.ok());
  EXPECT_EQ(img->info.width, 40);
  EXPECT_EQ(img->info.attrs["vox:split"], "6 (single step)");
  // The default camera frames the whole volume: the sphere is in the middle, not cut off.
  EXPECT_EQ(img->pixels["A"][15 * 40 + 20], 1.0f);
  for (int x = 0; x < 40; ++x) {
    EXPECT_EQ(img->pixels["A"][size_t(x)], 0.0f);
    EXPECT_EQ(img->pixels["A"][29 * 40 + size_t(x)], 0.0f);
  }
}

TEST_F(CliTest, TilesAndMergeEqualTheFullRender) {
  std::string cam = Write("cam.json", kCam);
  ASSERT_EQ(testing::RunCommand(Render("--cam " + cam + " -o " + Path("full.exr") +
                        " --tile-size 16 --quiet --split 3+3"))
                .code,
            0);
  std::string parts;
  for (int i = 1; i <= 3; ++i) {
    std::string p = Path("p" + std::to_string(i) + ".exr");
    RunResult r =
        testing::RunCommand(Render("--cam " + cam + " -o " + p + " --tile-size 16 --quiet --split 3 --tiles " +
                    std::to_string(i) + "/3"));
    ASSERT_EQ(r.code, 0) << r.output;
    parts += " " + p;
  }
  RunResult m = testing::RunCommand(std::string(VOX_MERGE_BIN) + parts + " -o " + Path("merged.exr") + " --quiet");
  ASSERT_EQ(m.code, 0) << m.output;
  auto full = ReadExr(Path("full.exr"));
  auto merged = ReadExr(Path("merged.exr"));
  ASSERT_TRUE(full.ok() && merged.ok());
  for (const auto& [name, pixels] : full->pixels)
    EXPECT_EQ(std::memcmp(pixels.data(), merged->pixels[name].data(), pixels.size() * 4), 0)
        << name;
  // A missing part is refused.
  RunResult bad = testing::RunCommand(std::string(VOX_MERGE_BIN) + " " + Path("p1.exr") + " " + Path("p3.exr") +
                       " -o " + Path("bad.exr"));
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("part 2/3 is missing"), std::string::npos) << bad.output;
}

TEST_F(CliTest, BadCameraFilesNameTheFieldAndFail) {
  struct Case {
    const char* json;
    const char* field;
  } cases[] = {
      {R"({"look_at":[0,0,0], "fov_deg":40, "width":64, "height":48})", "'position' is missing"},
      {R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":"wide", "width":64, "height":48})",
       "'fov_deg' must be a number"},
      {R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":40, "width":0, "height":48})",
       "'width'"},
      {R"({"position":[0,3,20], "look_at":[0,0,0], "up":[0,6,40], "fov_deg":40, "width":64, "height":48})",
       "'up' is parallel"},
      {R"({"position":[0,3,"NaN"], "look_at":[0,0,0], "fov_deg":40, "width":64, "height":48})",
       "'position[2]'"},
      {R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":40, "width":64, "height":48, "projection":"cylindrical"})",
       "'projection'"},
  };
  int k = 0;
  for (const Case& c : cases) {
    std::string cam = Write("bad" + std::to_string(k++) + ".json", c.json);
    RunResult r = testing::RunCommand(Render("--cam " + cam + " -o " + Path("x.exr") + " --quiet"));
    EXPECT_EQ(r.code, 1) << c.json;
    EXPECT_NE(r.output.find(c.field), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(cam), std::string::npos) << r.output;
  }
  std::string scene = Write("bad_scene.json", R"({"lights":[{"type":"directional"}]})");
  RunResult r = testing::RunCommand(
      Render("--cam " + Write("cam.json", kCam) + " --scene " + scene + " -o " + Path("x.exr")));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("lights[0].direction"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(scene), std::string::npos) << r.output;
}

TEST_F(CliTest, FogStoreTransmittanceIsExponential) {
  // A fog cube of density 0.6, index [8,24)^3 with voxel size 0.5: world [4,12)^3
  // (index_to_world = scale(0.5) * translate(0.5), as in the test volumes).
  StoreMeta meta = testing::TestMeta(5, GridClass::kFogVolume, 0.5);
  meta.brick_level = 2;
  std::vector<MemoryVoxel> voxels;
  for (int z = 8; z < 24; ++z)
    for (int y = 8; y < 24; ++y)
      for (int x = 8; x < 24; ++x) {
        MemoryVoxel v;
        v.x = uint64_t(x), v.y = uint64_t(y), v.z = uint64_t(z);
        v.attr.density = 0.6f;
        voxels.push_back(v);
      }
  ASSERT_TRUE(testing::WriteStore(Path("fog"), meta, voxels).ok());
  std::string cam = Write(
      "fogcam.json",
      R"({"position":[9,10.5,25], "look_at":[8,8,8], "fov_deg":40, "width":40, "height":40})");
  std::string scene =
      Write("fogscene.json",
            R"({"lights":[], "background":[1,1,1], "volume":{"absorption":0.4,"scattering":0}})");
  RunResult r =
      testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + Path("fog") + " --cam " + cam + " --scene " + scene +
           " -o " + Path("fog.exr") + " --quiet --stats " + Path("fog.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto img = ReadExr(Path("fog.exr"));
  ASSERT_TRUE(img.ok());
  auto c = ParseCamera(
      R"({"position":[9,10.5,25], "look_at":[8,8,8], "fov_deg":40, "width":40, "height":40})",
      "cam");
  ASSERT_TRUE(c.ok());
  int inside = 0;
  for (int j = 0; j < 40; ++j)
    for (int i = 0; i < 40; ++i) {
      WorldRay ray = c->PixelRay(i + 0.5, j + 0.5);
      double t0 = 0, t1 = 1e300;
      for (int a = 0; a < 3; ++a) {
        double ta = (4 - ray.origin[a]) / ray.dir[a], tb = (12 - ray.origin[a]) / ray.dir[a];
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
      }
      double len = t1 > t0 ? t1 - t0 : 0;
      inside += len > 0;
      // Premultiplied, without the background: no scattering, so no colour.
      ASSERT_NEAR(img->pixels["A"][size_t(j) * 40 + i], 1 - std::exp(-0.4 * 0.6 * len), 1e-3)
          << i << "," << j;
      ASSERT_EQ(img->pixels["R"][size_t(j) * 40 + i], 0.0f) << i << "," << j;
    }
  EXPECT_GT(inside, 200);
  std::ifstream in(Path("fog.json"));
  auto stats = nlohmann::json::parse(in);
  EXPECT_TRUE(stats["passes"]["volume"].get<bool>());
  EXPECT_EQ(stats["rays"]["shadow"], 0);
  EXPECT_EQ(stats["rays"]["volume"], 0);
}

// More parts than the image has tiles: legal (a part may be empty) but
// surely a mistake, so the render warns, saying how many tiles there are.
TEST_F(CliTest, TilesBeyondTheTileCountWarn) {
  std::string cam = Write("cam.json", kCam);  // 64x48: 4x3 tiles of 16 pixels
  RunResult empty = testing::RunCommand(
      Render("--cam " + cam + " -o " + Path("e.exr") + " --tile-size 16 --tiles 2/100"));
  ASSERT_EQ(empty.code, 0) << empty.output;
  EXPECT_NE(empty.output.find("vox-render: warning: --tiles 2/100: the 64x48 image has only 12 "
                              "tiles of 16 pixels, fewer than the 100 parts, so some parts are "
                              "empty; this part renders 0 tiles\n"),
            std::string::npos) << empty.output;
  RunResult last = testing::RunCommand(
      Render("--cam " + cam + " -o " + Path("l.exr") + " --tile-size 16 --tiles 100/100"));
  ASSERT_EQ(last.code, 0) << last.output;
  EXPECT_NE(last.output.find("this part renders 1 tile\n"), std::string::npos) << last.output;
  // As many parts as tiles: no warning.
  RunResult fits = testing::RunCommand(
      Render("--cam " + cam + " -o " + Path("f.exr") + " --tile-size 16 --tiles 12/12"));
  ASSERT_EQ(fits.code, 0) << fits.output;
  EXPECT_EQ(fits.output.find("warning"), std::string::npos) << fits.output;
}

// A sequence's output must be a frame pattern; the one suggested for a name
// holding a '%' is one the render then takes.
TEST_F(CliTest, SuggestedFramePatternIsAccepted) {
  std::string cam = Write("cam.json", kCam);
  RunResult r = testing::RunCommand(
      Render("--cam " + cam + " --turntable 2 --quiet -o '" + Path("tt.%s.exr") + "'"));
  EXPECT_EQ(r.code, 1) << r.output;
  const std::string suggested = Path("tt.%%s.%04d.exr");
  EXPECT_NE(r.output.find("give a frame pattern such as " + suggested + " "), std::string::npos)
      << r.output;
  RunResult ok = testing::RunCommand(
      Render("--cam " + cam + " --turntable 2 --quiet -o '" + suggested + "'"));
  ASSERT_EQ(ok.code, 0) << ok.output;
  EXPECT_TRUE(fs::exists(Path("tt.%s.0001.exr")));
  EXPECT_TRUE(fs::exists(Path("tt.%s.0002.exr")));
}

TEST_F(CliTest, BadFlagsAndMissingStore) {
  EXPECT_EQ(testing::RunCommand(Render("--tiles 4/3")).code, 2);
  EXPECT_EQ(testing::RunCommand(Render("--tile-size x")).code, 2);
  RunResult tile = testing::RunCommand(Render("--tile-size 0 --quiet -o " + Path("t.exr")));
  EXPECT_EQ(tile.code, 2);  // a bad value (docs/usage.md)
  EXPECT_NE(tile.output.find("--tile-size '0': expected a tile side in pixels, 8..4096"),
            std::string::npos) << tile.output;
  EXPECT_FALSE(fs::exists(Path("t.exr")));
  RunResult split_syntax = testing::RunCommand(Render("--split abc --quiet -o " + Path("t.exr")));
  EXPECT_EQ(split_syntax.code, 2);
  EXPECT_FALSE(fs::exists(Path("t.exr")));
  EXPECT_EQ(testing::RunCommand(Render("--bogus")).code, 2);
  RunResult split = testing::RunCommand(Render("--split 4+4 --quiet -o " + Path("s.exr")));
  EXPECT_EQ(split.code, 1);
  EXPECT_NE(split.output.find("6 levels"), std::string::npos) << split.output;
  // Flags that would do nothing are refused, saying why (exit 2, before any work).
  RunResult io = testing::RunCommand(Render("--io-threads 4 --quiet -o " + Path("io.exr")));
  EXPECT_EQ(io.code, 2);
  EXPECT_NE(io.output.find("--io-threads sets the background readers of --prefetch"),
            std::string::npos) << io.output;
  EXPECT_FALSE(fs::exists(Path("io.exr")));
  RunResult no_prefetch = testing::RunCommand(Render("--no-prefetch --quiet -o " + Path("np.exr")));
  EXPECT_EQ(no_prefetch.code, 2);
  EXPECT_NE(no_prefetch.output.find("--no-prefetch was removed"), std::string::npos)
      << no_prefetch.output;
  // With --prefetch, --io-threads is taken and the job uses it (at most the given number).
  RunResult with = testing::RunCommand(Render("--prefetch --io-threads 2 --quiet -o " + Path("io.exr") +
                                              " --stats " + Path("io.json")));
  ASSERT_EQ(with.code, 0) << with.output;
  std::ifstream io_stats(Path("io.json"));
  const auto io_json = nlohmann::json::parse(io_stats);
  EXPECT_GE(io_json["memory"]["io_threads"].get<int>(), 1);
  EXPECT_LE(io_json["memory"]["io_threads"].get<int>(), 2);
  RunResult missing = testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + Path("nostore") + " --quiet");
  EXPECT_EQ(missing.code, 1);
  EXPECT_NE(missing.output.find("nostore"), std::string::npos) << missing.output;
}

// An OpenVDB file given for the store: exit 1, and the vox-ingest command
// that makes the store from it (docs/usage.md).
TEST_F(CliTest, VdbFileSaysToRunVoxIngest) {
  // OpenVDB's magic number, then anything: the name and the bytes both tell.
  const std::string vdb = Write("bunny.vdb", std::string(" BDV", 4) + std::string(60, '\0'));
  RunResult r = testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + vdb + " -o " +
                                    Path("v.exr") + " --quiet");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("is an OpenVDB file, not a vox store"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("vox-ingest " + vdb + " " + Path("bunny_store")), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(Path("v.exr")));
  const std::string renamed = Write("volume.bin", std::string(" BDV", 4) + std::string(60, '\0'));
  r = testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + renamed + " --quiet");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("vox-ingest " + renamed + " " + renamed + "_store"), std::string::npos)
      << r.output;
  // Another file is still "not a store directory".
  r = testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + Write("notes.txt", "hello") +
                          " --quiet");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("is not a store directory"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("vox-ingest"), std::string::npos) << r.output;
}

// A camera without width and height renders at --size; without --size the
// error names the field and the flag.
TEST_F(CliTest, SizeFillsACameraWithoutOne) {
  const std::string cam =
      Write("sizeless.json", R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":40})");
  RunResult r = testing::RunCommand(
      Render("--cam " + cam + " --size 32x24 -o " + Path("s.exr") + " --quiet"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto info = ReadExrInfo(Path("s.exr"));
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->width, 32);
  EXPECT_EQ(info->height, 24);
  r = testing::RunCommand(Render("--cam " + cam + " -o " + Path("n.exr") + " --quiet"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find(cam + ": field 'width' is missing (give width and height, or "
                                "vox-render --size WxH)"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(Path("n.exr")));
}

}  // namespace
}  // namespace vox

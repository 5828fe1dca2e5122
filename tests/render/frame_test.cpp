// RenderFrame to tiled EXR: round trip through OpenEXR, header contents,
// split renders merged bit for bit, merge refusing parts that do not belong
// together, the PNG preview and the progress line.
#include "render/frame.h"

#include <Imath/half.h>
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <map>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "render/exr.h"
#include "render/merge.h"
#include "storage/store.h"
#include "tests/render/render_util.h"
#include "tests/render/store_util.h"
#include "tests/render/test_volumes.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using testing::Box;
using testing::MakeVolume;
using testing::Sphere;
using testing::TestMeta;

class FrameTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vox_frame_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
    vol_ = MakeVolume(TestMeta(5, GridClass::kLevelSet),
                      {Sphere({15, 17, 16}, 10), Box({2, 2, 2}, {8, 28, 6})});
    ASSERT_TRUE(vol_);
    cam_.position = {40, 30, 50};
    cam_.look_at = {16, 16, 16};
    cam_.fov_deg = 40;
    cam_.width = 83;  // not a multiple of the tile size
    cam_.height = 61;
    ASSERT_TRUE(cam_.Finalize().ok());
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) { return (dir_ / name).string(); }

  std::unique_ptr<Renderer> MakeRenderer(const Camera& cam, ImageLayers layers = {}) {
    RenderOptions o;
    o.layers = layers;
    auto r = Renderer::Create(vol_.get(), cam, scene_, o);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? std::move(r).value() : nullptr;
  }

  Status Frame(const Renderer& r, const std::string& path, PartSpec part = {}, int tile = 16,
               FrameStats* stats_out = nullptr) {
    FrameOptions fo;
    fo.exr_path = path;
    fo.threads = 2;
    fo.tile_size = tile;
    fo.part = part;
    FrameStats stats;
    Status s = RenderFrame(r, fo, &stats);
    if (stats_out) *stats_out = stats;
    return s;
  }

  // A 64^3 store ("store": a sphere shell, 8^3 bricks of 8^3 voxels) and a
  // 96x80 camera that sees it whole.
  void WriteShellStore(Camera* cam) {
    StoreMeta meta = TestMeta(6, GridClass::kLevelSet);
    std::vector<MemoryVoxel> voxels = testing::ShellVoxels(64, {31.5, 30.5, 32.5}, 22, 25);
    ASSERT_TRUE(testing::WriteStore(Path("store"), meta, voxels).ok());
    cam->position = {90, 70, 100};
    cam->look_at = {32, 32, 32};
    cam->fov_deg = 50;
    cam->width = 96;
    cam->height = 80;
    ASSERT_TRUE(cam->Finalize().ok());
  }

  fs::path dir_;
  std::unique_ptr<MemoryVolume> vol_;
  Camera cam_;
  Scene scene_;  // defaults: a shadow-casting key light
};

// Default output: R G B A as HALF (each the renderer's float rounded to the
// nearest half), Z and the layers as FLOAT, RLE-compressed.
TEST_F(FrameTest, HalfColourIsTheRenderersFloatsRounded) {
  ImageLayers layers;
  layers.normal = layers.voxel = true;
  auto r = MakeRenderer(cam_, layers);
  ASSERT_TRUE(r);
  ASSERT_TRUE(Frame(*r, Path("half.exr")).ok());
  testing::Image mem;
  RenderCounters counters;
  ASSERT_TRUE(testing::RenderToMemory(*r, &mem, &counters, 16).ok());
  auto img = ReadExr(Path("half.exr"));
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_FALSE(img->info.float_color);
  EXPECT_EQ(img->info.compression, "rle");
  size_t inexact = 0;
  for (const auto& [name, pixels] : mem.ch) {
    ASSERT_TRUE(img->pixels.count(name)) << name;
    const std::vector<float>& got = img->pixels[name];
    const bool half = name == "R" || name == "G" || name == "B" || name == "A";
    for (size_t i = 0; i < pixels.size(); ++i) {
      const float want = half ? float(Imath::half(pixels[i])) : pixels[i];
      ASSERT_EQ(std::memcmp(&want, &got[i], 4), 0) << name << " pixel " << i;
      inexact += want != pixels[i];
    }
  }
  EXPECT_GT(inexact, 0u);  // the colours do lose bits: the file is half
  // Half colour is smaller on disk than float colour.
  ImageLayers fl = layers;
  fl.float_color = true;
  auto rf = MakeRenderer(cam_, fl);
  ASSERT_TRUE(rf);
  ASSERT_TRUE(Frame(*rf, Path("float.exr")).ok());
  EXPECT_LT(fs::file_size(Path("half.exr")), fs::file_size(Path("float.exr")));
}

// Every compression vox-render offers reads back to the same pixels.
TEST_F(FrameTest, CompressionsKeepThePixels) {
  EXPECT_FALSE(ParseExrCompression("b44").ok());
  EXPECT_NE(ParseExrCompression("zip2").status().message().find("expected zip, zips"),
            std::string::npos);
  auto r = MakeRenderer(cam_);
  ASSERT_TRUE(r);
  std::map<std::string, std::vector<float>> first;
  for (const char* name : {"zip", "zips", "piz", "rle", "none"}) {
    auto c = ParseExrCompression(name);
    ASSERT_TRUE(c.ok()) << name;
    EXPECT_STREQ(ExrCompressionName(*c), name);
    FrameOptions fo;
    fo.exr_path = Path(std::string(name) + ".exr");
    fo.threads = 2;
    fo.tile_size = 16;
    fo.compression = *c;
    FrameStats stats;
    ASSERT_TRUE(RenderFrame(*r, fo, &stats).ok()) << name;
    auto img = ReadExr(fo.exr_path);
    ASSERT_TRUE(img.ok()) << img.status().ToString();
    EXPECT_EQ(img->info.compression, name);
    if (first.empty()) first = img->pixels;
    for (const auto& [ch, px] : first)
      EXPECT_EQ(std::memcmp(px.data(), img->pixels[ch].data(), px.size() * 4), 0) << name << " " << ch;
  }
}

TEST_F(FrameTest, ExrRoundTripMatchesTheRenderer) {
  ImageLayers layers;
  layers.normal = layers.voxel = layers.position = layers.distance = true;
  layers.float_color = true;  // --float: every channel bit for bit
  auto r = MakeRenderer(cam_, layers);
  ASSERT_TRUE(r);
  FrameStats stats;
  ASSERT_TRUE(Frame(*r, Path("full.exr"), {}, 16, &stats).ok());
  testing::Image mem;
  RenderCounters counters;
  ASSERT_TRUE(testing::RenderToMemory(*r, &mem, &counters, 16).ok());
  auto img = ReadExr(Path("full.exr"));
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  EXPECT_EQ(img->info.width, 83);
  EXPECT_EQ(img->info.height, 61);
  EXPECT_EQ(img->info.tile, 16);
  EXPECT_TRUE(img->info.complete);
  size_t channels = 0;
  for (int c = 0; c < kNumChannels; ++c) channels += layers.Has(c);
  EXPECT_EQ(img->pixels.size(), channels);
  for (const auto& [name, pixels] : mem.ch) {
    ASSERT_TRUE(img->pixels.count(name)) << name;
    EXPECT_EQ(std::memcmp(pixels.data(), img->pixels[name].data(), pixels.size() * 4), 0) << name;
  }
  // Counters match the in-memory render; every tile was written.
  EXPECT_EQ(stats.counters.rays[kRayPrimary], counters.rays[kRayPrimary]);
  EXPECT_EQ(stats.counters.rays[kRayShadow], counters.rays[kRayShadow]);
  EXPECT_GT(stats.counters.rays[kRayShadow], 0u);
  EXPECT_EQ(stats.tiles, 6 * 4);
  // Header: camera, split, passes, part, timings.
  EXPECT_EQ(img->info.attrs["vox:camera"], cam_.ToJson());
  EXPECT_EQ(img->info.attrs["vox:split"], r->SplitString());
  EXPECT_EQ(img->info.attrs["vox:part"], "1/1");
  EXPECT_EQ(img->info.attrs["vox:store"], "memory");
  EXPECT_NE(img->info.attrs["vox:passes"].find("shadows"), std::string::npos);
  EXPECT_GT(img->info.render_seconds, 0.0);
  auto timings = nlohmann::json::parse(img->info.attrs["vox:timings"]);
  EXPECT_EQ(timings["threads"], 2);
  EXPECT_NEAR(timings["render_seconds"].get<double>(), img->info.render_seconds, 1e-3);
  // The stats document has the counters users read: rays by kind, moves, bricks.
  auto js = nlohmann::json::parse(StatsJson(*r, stats, {{"total_seconds", 1.0}}));
  EXPECT_EQ(js["rays"]["primary"], 83 * 61);
  EXPECT_EQ(js["rays"]["shadow"], stats.counters.rays[kRayShadow]);
  EXPECT_EQ(js["rays"]["reflection"], 0);
  EXPECT_GT(js["dda"]["moves"].get<uint64_t>(), 0u);
  EXPECT_TRUE(js["dda"].contains("transitions"));
  EXPECT_TRUE(js["cache"].contains("bricks_paged_in"));
  EXPECT_TRUE(js["cache"].contains("hits"));
  EXPECT_TRUE(js["timings"].contains("render_seconds"));
}

TEST_F(FrameTest, PartsMergeBitForBitIntoTheFullRender) {
  auto r = MakeRenderer(cam_);
  ASSERT_TRUE(r);
  ASSERT_TRUE(Frame(*r, Path("full.exr")).ok());
  std::vector<std::string> parts;
  int64_t tiles = 0;
  for (int i = 1; i <= 3; ++i) {
    parts.push_back(Path("part" + std::to_string(i) + ".exr"));
    FrameStats st;
    ASSERT_TRUE(Frame(*r, parts.back(), PartSpec{i, 3}, 16, &st).ok());
    tiles += st.tiles;
    auto info = ReadExrInfo(parts.back());
    ASSERT_TRUE(info.ok());
    EXPECT_FALSE(info->complete);
  }
  EXPECT_EQ(tiles, 24);
  MergeResult res;
  // Any order of the part files.
  Status s = MergeParts({parts[2], parts[0], parts[1]}, Path("merged.exr"), &res);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(res.parts, 3);
  EXPECT_EQ(res.tiles, 24);
  auto full = ReadExr(Path("full.exr"));
  auto merged = ReadExr(Path("merged.exr"));
  ASSERT_TRUE(full.ok() && merged.ok());
  ASSERT_EQ(full->pixels.size(), merged->pixels.size());
  for (const auto& [name, pixels] : full->pixels)
    EXPECT_EQ(std::memcmp(pixels.data(), merged->pixels[name].data(), pixels.size() * 4), 0)
        << name;
  EXPECT_EQ(merged->info.attrs["vox:camera"], full->info.attrs["vox:camera"]);
  // Parts are written uncompressed; the merged image is ZIP-compressed, half
  // colour like the parts.
  EXPECT_EQ(ReadExrInfo(parts[0])->compression, "none");
  EXPECT_EQ(merged->info.compression, "zip");
  EXPECT_FALSE(merged->info.float_color);

  // Refusals, each naming the culprit.
  auto expect_error = [&](const std::vector<std::string>& list, const std::string& needle) {
    Status e = MergeParts(list, Path("bad.exr"));
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.message().find(needle), std::string::npos) << e.ToString();
  };
  expect_error({parts[0], parts[1]}, "part 3/3 is missing");
  expect_error({parts[0], parts[1], parts[1]}, "overlap");
  expect_error({parts[0], parts[1], parts[2], Path("full.exr")}, "part count");
  expect_error({parts[0], Path("nonexistent.exr")}, "nonexistent.exr");
  // A part rendered with another camera.
  Camera other = cam_;
  other.position.x += 1;
  ASSERT_TRUE(other.Finalize().ok());
  auto r2 = MakeRenderer(other);
  ASSERT_TRUE(Frame(*r2, Path("other2.exr"), PartSpec{2, 3}).ok());
  expect_error({parts[0], Path("other2.exr"), parts[2]}, "vox:camera");
  // Another tile size.
  ASSERT_TRUE(Frame(*r, Path("tile32.exr"), PartSpec{2, 3}, 32).ok());
  expect_error({parts[0], Path("tile32.exr"), parts[2]}, "tile size");
  // A part with float colour (--float) among half ones.
  {
    ImageLayers fl;
    fl.float_color = true;
    auto rf = MakeRenderer(cam_, fl);
    ASSERT_TRUE(Frame(*rf, Path("float2.exr"), PartSpec{2, 3}).ok());
    expect_error({parts[0], Path("float2.exr"), parts[2]}, "colour pixel type differs (float vs half)");
    // Float parts merge into a float image, bit for bit.
    std::vector<std::string> fparts;
    for (int i = 1; i <= 3; ++i) {
      fparts.push_back(Path("fpart" + std::to_string(i) + ".exr"));
      ASSERT_TRUE(Frame(*rf, fparts.back(), PartSpec{i, 3}).ok());
    }
    ASSERT_TRUE(Frame(*rf, Path("ffull.exr")).ok());
    ASSERT_TRUE(MergeParts(fparts, Path("fmerged.exr")).ok());
    auto ff = ReadExr(Path("ffull.exr"));
    auto fm = ReadExr(Path("fmerged.exr"));
    ASSERT_TRUE(ff.ok() && fm.ok());
    EXPECT_TRUE(fm->info.float_color);
    for (const auto& [name, pixels] : ff->pixels)
      EXPECT_EQ(std::memcmp(pixels.data(), fm->pixels[name].data(), pixels.size() * 4), 0)
          << name;
  }
  // A part whose render stopped early: same header, one tile only.
  {
    auto info = ReadExrInfo(parts[1]);
    ASSERT_TRUE(info.ok());
    ExrAttributes attrs = info->attrs;
    attrs.erase("vox:timings");
    auto w = TiledExrWriter::Create(Path("short.exr"), 83, 61, 16, {}, attrs);
    ASSERT_TRUE(w.ok());
    TileBuffer buf;
    buf.Allocate(16, {});
    TileLayout layout(83, 61, 16);
    int64_t b = 0, e = 0;
    layout.PartRange({2, 3}, &b, &e);
    ASSERT_TRUE((*w)->WriteTile(layout.order()[size_t(b)], buf).ok());
    ASSERT_TRUE((*w)->Close().ok());
  }
  expect_error({parts[0], Path("short.exr"), parts[2]}, "lacks tile");
}

TEST_F(FrameTest, TileOrderAndParts) {
  TileLayout layout(100, 50, 16);
  EXPECT_EQ(layout.num_tiles(), 7 * 4);
  std::vector<int> seen(28, 0);
  for (const TileRect& t : layout.order()) ++seen[size_t(t.ty * 7 + t.tx)];
  for (int s : seen) EXPECT_EQ(s, 1);
  // Morton order: the first four tiles are the top-left 2x2 block.
  for (int k = 0; k < 4; ++k) {
    EXPECT_LT(layout.order()[size_t(k)].tx, 2);
    EXPECT_LT(layout.order()[size_t(k)].ty, 2);
  }
  EXPECT_EQ(layout.Rect(6, 3).w, 4);
  EXPECT_EQ(layout.Rect(6, 3).h, 2);
  int64_t covered = 0, prev_end = 0;
  for (int i = 1; i <= 5; ++i) {
    int64_t b, e;
    layout.PartRange({i, 5}, &b, &e);
    EXPECT_EQ(b, prev_end);
    covered += e - b;
    prev_end = e;
  }
  EXPECT_EQ(covered, 28);
  EXPECT_FALSE(ParsePartSpec("0/3").ok());
  EXPECT_FALSE(ParsePartSpec("4/3").ok());
  EXPECT_FALSE(ParsePartSpec("1/").ok());
  EXPECT_FALSE(ParsePartSpec("a/b").ok());
  EXPECT_TRUE(ParsePartSpec("3/3").ok());
}

TEST_F(FrameTest, PngPreview) {
  scene_.background_top = scene_.background_bottom = {0.2, 0.2, 0.2};
  auto r = MakeRenderer(cam_);
  ASSERT_TRUE(Frame(*r, Path("full.exr")).ok());
  // The EXR is premultiplied: the preview composes it over the background.
  const PreviewBackground grey = [](int, int, float rgb[3]) { rgb[0] = rgb[1] = rgb[2] = 0.2f; };
  ASSERT_TRUE(WritePngPreview(Path("full.exr"), Path("full.png"), grey).ok());
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&image, Path("full.png").c_str()));
  EXPECT_EQ(image.width, 83u);
  EXPECT_EQ(image.height, 61u);
  image.format = PNG_FORMAT_RGB;
  std::vector<uint8_t> px(PNG_IMAGE_SIZE(image));
  ASSERT_TRUE(png_image_finish_read(&image, nullptr, px.data(), 0, nullptr));
  // Top-left pixel is background 0.2 linear = 124 in sRGB.
  EXPECT_EQ(px[0], 124);
  // A partial EXR has no preview.
  ASSERT_TRUE(Frame(*r, Path("part.exr"), PartSpec{1, 2}).ok());
  EXPECT_FALSE(WritePngPreview(Path("part.exr"), Path("part.png")).ok());
}

// A volume whose bricks or attributes fail to load, as a corrupt store's would.
class FailingVolume : public Volume, public BrickSource {
 public:
  FailingVolume(MemoryVolume* base, bool fail_bricks) : base_(base), fail_bricks_(fail_bricks) {}
  const StoreMeta& meta() const override { return base_->meta(); }
  OctreeView view() override {
    OctreeView v = base_->view();
    v.bricks = this;
    return v;
  }
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    if (fail_bricks_)
      return CorruptionError("store/bricks.vxb: brick " + std::to_string(id) +
                             " checksum mismatch");
    return base_->view().bricks->FetchBrick(id);
  }
  StatusOr<VoxelAttributes> Attributes(uint32_t, uint32_t) override {
    return IoError("store/bricks.vxb: read failed");
  }
  std::string description() const override { return "failing"; }

 private:
  MemoryVolume* base_;
  bool fail_bricks_;
};

// The library checks the frame's options and the camera, once: the tools
// only parse flags.
TEST_F(FrameTest, BadOptionsAndUnfinalisedCamerasAreRefused) {
  auto r = MakeRenderer(cam_);
  ASSERT_TRUE(r);
  for (int tile : {0, 7, 4097, -16}) {
    Status s = Frame(*r, Path("bad_tile.exr"), {}, tile);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << tile;
    EXPECT_NE(s.message().find("tile size " + std::to_string(tile)), std::string::npos)
        << s.ToString();
    EXPECT_FALSE(fs::exists(Path("bad_tile.exr")));
  }
  for (int tile : {8, 4096}) EXPECT_TRUE(Frame(*r, "", {}, tile).ok()) << tile;
  FrameOptions fo;
  fo.threads = -1;
  FrameStats stats;
  Status s = RenderFrame(*r, fo, &stats);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("threads -1"), std::string::npos) << s.ToString();

  Camera raw;  // fields set, Finalize() never called
  raw.position = cam_.position;
  raw.look_at = cam_.look_at;
  raw.width = 8;
  raw.height = 8;
  EXPECT_FALSE(raw.finalized());
  auto refused = Renderer::Create(vol_.get(), raw, scene_, {});
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("camera"), std::string::npos);
  ASSERT_TRUE(raw.Finalize().ok());
  EXPECT_TRUE(Renderer::Create(vol_.get(), raw, scene_, {}).ok());
  raw.fov_deg = 0;  // a failed Finalize() leaves it unfinalised
  EXPECT_FALSE(raw.Finalize().ok());
  EXPECT_FALSE(Renderer::Create(vol_.get(), raw, scene_, {}).ok());
}

TEST_F(FrameTest, BrickAndAttributeErrorsStopTheRenderWithAMessage) {
  for (bool fail_bricks : {true, false}) {
    FailingVolume bad(vol_.get(), fail_bricks);
    auto r = Renderer::Create(&bad, cam_, scene_, {});
    ASSERT_TRUE(r.ok());
    FrameOptions fo;
    fo.exr_path = Path("bad.exr");
    fo.threads = 2;
    fo.tile_size = 16;
    FrameStats stats;
    Status s = RenderFrame(**r, fo, &stats);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.code(), fail_bricks ? StatusCode::kCorruption : StatusCode::kIoError);
    EXPECT_NE(s.message().find("store/bricks.vxb"), std::string::npos) << s.ToString();
    EXPECT_NE(s.message().find("tile ("), std::string::npos) << s.ToString();
    EXPECT_LT(stats.tiles, 24);
  }
}

// Two render threads on a store whose cache holds a few bricks: bricks are
// evicted while the threads' brick tables still lend them to the tracers,
// and the image is bit for bit the one rendered with a cache that holds all.
TEST_F(FrameTest, TinyCacheRendersTheSameImage) {
  Camera cam;
  ASSERT_NO_FATAL_FAILURE(WriteShellStore(&cam));
  std::map<std::string, std::vector<float>> images[2];
  for (int tiny : {0, 1}) {
    OpenOptions oo;
    oo.cache_bytes = tiny ? (16u << 10) : (64u << 20);
    auto vol = Store::Open(Path("store"), oo);
    ASSERT_TRUE(vol.ok()) << vol.status().ToString();
    RenderOptions ro;
    ro.layers.normal = true;
    auto r = Renderer::Create(vol->get(), cam, scene_, ro);  // shadows: secondary rays too
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    FrameOptions fo;
    fo.exr_path = Path(tiny ? "tiny.exr" : "big.exr");
    fo.threads = 2;
    fo.tile_size = 8;
    FrameStats stats;
    Status s = RenderFrame(**r, fo, &stats);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_GT(stats.counters.rays[kRayShadow], 0u);
    const CacheStats& c = stats.cache_end;
    if (tiny) {
      EXPECT_GT(c.evictions, 0u);
      EXPECT_LE(c.bytes_resident, c.capacity);
    } else {
      EXPECT_EQ(c.evictions, 0u);
    }
    auto img = ReadExr(fo.exr_path);
    ASSERT_TRUE(img.ok()) << img.status().ToString();
    images[tiny] = img->pixels;
  }
  ASSERT_FALSE(images[0].empty());
  for (const auto& [name, px] : images[0]) {
    ASSERT_TRUE(images[1].count(name)) << name;
    EXPECT_EQ(px, images[1][name]) << "channel " << name;
  }
  size_t hits = 0;
  for (float a : images[0]["A"]) hits += a > 0;
  EXPECT_GT(hits, 1000u);  // the sphere fills much of the frame
}

// Reading ahead (the scout's first bricks, deferred misses read in the
// background) changes when bricks are read, never a pixel or a counter of
// the work done: bit-identical images and equal ray and DDA counters against
// waiting for each brick, with a cache big enough to hold the frame and one
// so small that bricks read ahead are evicted before use.
TEST_F(FrameTest, ReadingAheadChangesNoPixelAndNoCounter) {
  Camera cam;
  ASSERT_NO_FATAL_FAILURE(WriteShellStore(&cam));
  for (size_t cache : {size_t(64) << 20, size_t(24) << 10}) {
    std::map<std::string, std::vector<float>> images[2];
    RenderCounters counters[2];
    for (int ahead : {0, 1}) {
      OpenOptions oo;
      oo.cache_bytes = cache;
      oo.io_threads = 3;
      auto vol = Store::Open(Path("store"), oo);
      ASSERT_TRUE(vol.ok()) << vol.status().ToString();
      Store* store = vol->get();
      RenderOptions ro;
      ro.layers.normal = true;
      ro.layers.voxel = true;
      // Bricks asked for ahead: whether the I/O threads read them before a
      // waiting pass does depends on the machine's load, the asking does not.
      std::atomic<uint64_t> asked{0};
      if (ahead)
        ro.read_ahead = [store, &asked](std::span<const uint32_t> ids) {
          asked += ids.size();
          store->Prefetch(ids);
        };
      auto r = Renderer::Create(store, cam, scene_, ro);  // shadows: secondary rays too
      ASSERT_TRUE(r.ok()) << r.status().ToString();
      FrameOptions fo;
      fo.exr_path = Path("ahead" + std::to_string(ahead) + ".exr");
      fo.threads = 2;
      fo.tile_size = 16;
      if (ahead) {
        fo.prefetch = [store](std::span<const uint32_t> ids) { store->Prefetch(ids); };
        fo.prefetch_backlog = [store] { return store->PrefetchBacklog(); };
        fo.prefetch_limit = cache / 4;
      }
      FrameStats stats;
      Status s = RenderFrame(**r, fo, &stats);
      ASSERT_TRUE(s.ok()) << s.ToString();
      counters[ahead] = stats.counters;
      if (ahead) {
        EXPECT_GT(asked.load(), 0u) << "cache " << cache;
        EXPECT_GT(stats.counters.deferred_pixels, 0u) << "cache " << cache;
      } else {
        EXPECT_EQ(stats.counters.deferred_pixels, 0u);
      }
      auto img = ReadExr(fo.exr_path);
      ASSERT_TRUE(img.ok()) << img.status().ToString();
      images[ahead] = img->pixels;
    }
    ASSERT_FALSE(images[0].empty());
    for (const auto& [name, px] : images[0]) {
      ASSERT_TRUE(images[1].count(name)) << name;
      // As bits: misses are NaN in the voxel layer.
      ASSERT_EQ(px.size(), images[1][name].size());
      EXPECT_EQ(std::memcmp(px.data(), images[1][name].data(), px.size() * sizeof(float)), 0)
          << "channel " << name << ", cache " << cache;
    }
    for (int k = 0; k < kNumRayKinds; ++k) EXPECT_EQ(counters[0].rays[k], counters[1].rays[k]) << k;
    EXPECT_EQ(counters[0].pixels, counters[1].pixels);
    EXPECT_EQ(counters[0].hit_pixels, counters[1].hit_pixels);
    EXPECT_EQ(counters[0].attribute_lookups, counters[1].attribute_lookups);
    EXPECT_EQ(counters[0].trace.brick_fetches, counters[1].trace.brick_fetches);
    EXPECT_GT(counters[0].rays[kRayShadow], 0u);
  }
}

TEST(ProgressTest, LineShowsTilesRateCacheAndTimeLeft) {
  ProgressSnapshot s;
  s.tiles_done = 25;
  s.tiles_total = 100;
  s.rays = 2000000;
  s.cache_hits = 90;
  s.cache_misses = 10;
  std::string line = ProgressLine(s, 2.0);
  EXPECT_NE(line.find("tiles 25/100"), std::string::npos) << line;
  EXPECT_NE(line.find("1.00M rays/s"), std::string::npos) << line;
  EXPECT_NE(line.find("cache hits 90%"), std::string::npos) << line;
  EXPECT_NE(line.find("left 6.0s"), std::string::npos) << line;
}

}  // namespace
}  // namespace vox

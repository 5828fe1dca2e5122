// The EXR header check (render/internal/exr_header.h), starting from inputs
// the exr fuzz target found: attribute sizes that claim more bytes than the
// file holds, and a channel list whose declared size disagrees with its
// content (which desynchronises OpenEXR's reading of the attributes after
// it). Headers OpenEXR itself writes, with every attribute type it knows and
// several parts, pass the check; so do vox's files of every compression.
#include <OpenEXR/ImfBoxAttribute.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfChromaticitiesAttribute.h>
#include <OpenEXR/ImfCompressionAttribute.h>
#include <OpenEXR/ImfDoubleAttribute.h>
#include <OpenEXR/ImfEnvmapAttribute.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFloatVectorAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfKeyCodeAttribute.h>
#include <OpenEXR/ImfLineOrderAttribute.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfPreviewImageAttribute.h>
#include <OpenEXR/ImfRationalAttribute.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <OpenEXR/ImfTileDescriptionAttribute.h>
#include <OpenEXR/ImfTiledOutputFile.h>
#include <OpenEXR/ImfTimeCodeAttribute.h>
#include <OpenEXR/ImfVecAttribute.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "render/exr.h"
#include "render/internal/exr_header.h"
#include "render/merge.h"
#include "render/tiles.h"

namespace vox {
namespace {

std::string TempPath(const std::string& tag) {
  return "/tmp/vox-exr-header-" + std::to_string(getpid()) + "-" + tag + ".exr";
}

void Put(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string Bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

std::string U32(uint32_t v) {
  std::string s;
  for (int i = 0; i < 4; ++i) s.push_back(char((v >> (8 * i)) & 0xff));
  return s;
}

std::string Attr(const std::string& name, const std::string& type, uint32_t size,
                 const std::string& value) {
  return name + '\0' + type + '\0' + U32(size) + value;
}
std::string Attr(const std::string& name, const std::string& type, const std::string& value) {
  return Attr(name, type, uint32_t(value.size()), value);
}

std::string Magic(uint32_t flags) { return std::string("\x76\x2f\x31\x01", 4) + U32(2 | flags); }

// A channel list as OpenEXR writes it: (name NUL, type, pLinear, 3 reserved,
// xSampling, ySampling)* NUL.
std::string Channels(const std::vector<std::string>& names, uint32_t pixel_type = 2) {
  std::string v;
  for (const std::string& n : names) v += n + '\0' + U32(pixel_type) + U32(0) + U32(1) + U32(1);
  return v + '\0';
}

// Header bytes followed by some padding, standing in for the rest of a file.
std::string File(const std::string& header) { return header + std::string(64, '\x55'); }

Status Check(const std::string& tag, const std::string& bytes) {
  const std::string path = TempPath(tag);
  Put(path, bytes);
  Status s = CheckExrHeaders(path);
  std::remove(path.c_str());
  return s;
}

bool Has(const Status& s, const std::string& text) {
  return s.message().find(text) != std::string::npos;
}

TEST(ExrHeader, AttributeLargerThanTheFileIsRefused) {
  const std::string path = TempPath("huge");
  auto header = [](uint32_t size) { return Magic(0x200) + Attr("comments", "string", size, "abc"); };
  Put(path, header(1870004224u));
  auto info = ReadExrInfo(path);
  ASSERT_FALSE(info.ok());
  EXPECT_TRUE(Has(info.status(), path)) << info.status().ToString();
  EXPECT_TRUE(Has(info.status(), "comments (string) claims 1870004224 bytes"))
      << info.status().ToString();
  EXPECT_FALSE(ReadExr(path).ok());
  EXPECT_FALSE(MergeParts({path}, path + ".out.exr").ok());
  // The same header with an honest size reaches OpenEXR, which reports the
  // rest of the file missing itself.
  Put(path, header(3));
  auto honest = ReadExrInfo(path);
  ASSERT_FALSE(honest.ok());
  EXPECT_FALSE(Has(honest.status(), "claims")) << honest.status().ToString();
  std::remove(path.c_str());
}

// The fuzzer's finding: a channel list whose declared size is not what its
// entries take. OpenEXR reads the list to its empty name whatever the size,
// then reads the next attribute from the wrong offset.
TEST(ExrHeader, ChannelListSizeDisagreeingWithItsContentIsRefused) {
  const std::string list = Channels({"R", "G", "B"});  // 3 * (2 + 16) + 1 = 55 bytes
  ASSERT_EQ(list.size(), 55u);
  const std::string after = Attr("comments", "string", "after");
  EXPECT_TRUE(Check("cl-ok", File(Magic(0x200) + Attr("channels", "chlist", list) + after + '\0'))
                  .ok());
  for (uint32_t declared : {37u, 54u, 56u, 60u}) {
    Status s = Check("cl", File(Magic(0x200) + Attr("channels", "chlist", declared, list) + after +
                                '\0'));
    ASSERT_FALSE(s.ok()) << declared;
    EXPECT_TRUE(Has(s, "channels (chlist) declares " + std::to_string(declared) + " bytes"))
        << s.ToString();
    EXPECT_TRUE(Has(s, declared < 55 ? "holds more" : "holds 55")) << s.ToString();
  }
  Status bad_type = Check("cl-type", File(Magic(0x200) +
                                          Attr("channels", "chlist", Channels({"Z"}, 7)) + '\0'));
  EXPECT_TRUE(Has(bad_type, "channel Z has the unknown pixel type 7")) << bad_type.ToString();
  Status long_name = Check(
      "cl-name", File(Magic(0x200) + Attr("channels", "chlist", Channels({std::string(300, 'c')})) +
                      '\0'));
  EXPECT_TRUE(Has(long_name, "channel name is longer than 255")) << long_name.ToString();
}

// The same desync in a real file OpenEXR wrote, through every reader.
TEST(ExrHeader, RealFileWithAMutatedChannelListSizeIsRefusedByEveryReader) {
  const std::string path = TempPath("real");
  auto w = TiledExrWriter::Create(path, 20, 10, 16, {}, {{"vox:note", "x"}});
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  TileBuffer buf;
  buf.Allocate(16, {});
  const TileLayout layout(20, 10, 16);
  for (const TileRect& t : layout.order()) ASSERT_TRUE((*w)->WriteTile(t, buf).ok());
  ASSERT_TRUE((*w)->Close().ok());
  ASSERT_TRUE(ReadExrInfo(path).ok());
  std::string bytes = Bytes(path);
  const std::string key = std::string("channels\0chlist\0", 16);
  const size_t at = bytes.find(key);
  ASSERT_NE(at, std::string::npos);
  bytes[at + key.size()] = char(uint8_t(bytes[at + key.size()]) - 18);  // one entry fewer
  Put(path, bytes);
  auto info = ReadExrInfo(path);
  ASSERT_FALSE(info.ok());
  EXPECT_TRUE(Has(info.status(), path + ": EXR header attribute channels (chlist) declares"))
      << info.status().ToString();
  EXPECT_FALSE(ReadExr(path).ok());
  EXPECT_FALSE(WritePngPreview(path, path + ".png").ok());
  auto merged = MergeParts({path}, path + ".out.exr");
  EXPECT_TRUE(Has(merged, "channels (chlist)")) << merged.ToString();
  std::remove(path.c_str());
}

TEST(ExrHeader, FixedSizeTypesMustDeclareTheirSize) {
  const std::vector<std::pair<std::string, uint32_t>> types = {
      {"box2i", 16}, {"box2f", 16}, {"compression", 1}, {"chromaticities", 32},
      {"deepImageState", 1}, {"double", 8}, {"envmap", 1}, {"float", 4}, {"int", 4},
      {"keycode", 28}, {"lineOrder", 1}, {"m33f", 36}, {"m33d", 72}, {"m44f", 64},
      {"m44d", 128}, {"rational", 8}, {"tiledesc", 9}, {"timecode", 8}, {"v2i", 8},
      {"v2f", 8}, {"v2d", 16}, {"v3i", 12}, {"v3f", 12}, {"v3d", 24}};
  for (const auto& [type, size] : types) {
    const std::string value(size + 4, '\0');
    EXPECT_TRUE(Check("fixed", File(Magic(0x200) + Attr("a", type, size, value.substr(0, size)) +
                                    '\0'))
                    .ok())
        << type;
    for (uint32_t wrong : {size - 1, size + 4}) {
      Status s = Check("fixed", File(Magic(0x200) + Attr("a", type, wrong, value.substr(0, wrong)) +
                                     '\0'));
      EXPECT_TRUE(Has(s, "attribute a (" + type + ") declares " + std::to_string(wrong) +
                             " bytes but its value holds"))
          << type << " " << s.ToString();
    }
  }
}

TEST(ExrHeader, VariableSizeTypesAreParsed) {
  auto one = [](const std::string& attr) { return File(Magic(0x200) + attr + '\0'); };
  // stringvector: (length, bytes)* filling the declared size exactly.
  const std::string sv = U32(3) + "abc" + U32(0) + U32(2) + "de";
  EXPECT_TRUE(Check("sv", one(Attr("s", "stringvector", sv))).ok());
  EXPECT_TRUE(Has(Check("sv", one(Attr("s", "stringvector", U32(9) + "abc"))), "a string of 9"));
  EXPECT_TRUE(Has(Check("sv", one(Attr("s", "stringvector", sv + "xy"))), "declares 19 bytes"));
  // preview: width, height, 4 bytes a pixel.
  EXPECT_TRUE(Check("pv", one(Attr("p", "preview", U32(2) + U32(3) + std::string(24, 'p')))).ok());
  EXPECT_TRUE(Has(Check("pv", one(Attr("p", "preview", U32(2) + U32(4) + std::string(24, 'p')))),
                  "p (preview) declares 32 bytes"));
  // floatvector: whole floats.
  EXPECT_TRUE(Check("fv", one(Attr("f", "floatvector", std::string(8, 'f')))).ok());
  EXPECT_TRUE(Has(Check("fv", one(Attr("f", "floatvector", std::string(6, 'f')))),
                  "f (floatvector) declares 6 bytes but its value holds 4"));
  // string and unknown types: any size within the file.
  EXPECT_TRUE(Check("st", one(Attr("s", "string", std::string(40, 's')))).ok());
  EXPECT_TRUE(Check("un", one(Attr("u", "vox-own-type", std::string(40, 'u')))).ok());
  EXPECT_TRUE(Has(Check("un", one(Attr("u", "vox-own-type", 1000, std::string(40, 'u')))),
                  "u (vox-own-type) claims 1000 bytes"));
  // Sizes OpenEXR reads as negative, and names longer than OpenEXR's 255.
  EXPECT_TRUE(Has(Check("neg", one(Attr("n", "string", 0x80000000u, ""))), "negative size"));
  EXPECT_TRUE(Has(Check("name", one(Attr(std::string(256, 'n'), "int", U32(1)))),
                  "name longer than 255"));
  // A header without its terminating NUL.
  EXPECT_TRUE(Has(Check("trunc", Magic(0x200) + Attr("i", "int", U32(1))), "truncated"));
}

std::string Box(int32_t x0, int32_t y0, int32_t x1, int32_t y1) {
  return U32(uint32_t(x0)) + U32(uint32_t(y0)) + U32(uint32_t(x1)) + U32(uint32_t(y1));
}
std::string Tiles(uint32_t x, uint32_t y) { return U32(x) + U32(y) + '\0'; }

// The exr fuzz target's next finding: a consistent header whose tile
// description (8 x 16056328 pixels for a 24 x 16 image) makes OpenEXR
// allocate a 1.5 GB tile buffer. Tiles and data windows beyond what vox
// writes are refused; vox's own geometry passes.
TEST(ExrHeader, TilesAndDataWindowsBeyondVoxLimitsAreRefused) {
  auto header = [](const std::string& window, const std::string& tiles) {
    return File(Magic(0x200) + Attr("dataWindow", "box2i", window) +
                Attr("tiles", "tiledesc", tiles) + '\0');
  };
  EXPECT_TRUE(Check("geo", header(Box(0, 0, 23, 15), Tiles(64, 64))).ok());
  EXPECT_TRUE(Check("geo", header(Box(-5, 7, 1919, 1086), Tiles(4096, 8))).ok());
  Status s = Check("geo", header(Box(0, 0, 23, 15), Tiles(8, 16056328)));
  EXPECT_TRUE(Has(s, "tiles of 8 x 16056328 pixels (vox writes at most 4096")) << s.ToString();
  EXPECT_TRUE(Has(Check("geo", header(Box(0, 0, 23, 15), Tiles(0, 8))), "tiles of 0 x 8"));
  s = Check("geo", header(Box(0, 0, -3, 15), Tiles(8, 8)));
  EXPECT_TRUE(Has(s, "data window of -2 x 16 pixels")) << s.ToString();
  s = Check("geo", header(Box(INT32_MIN, 0, INT32_MAX, 0), Tiles(8, 8)));
  EXPECT_TRUE(Has(s, "data window of 4294967296 x 1 pixels")) << s.ToString();
  s = Check("geo", header(Box(0, 0, (1 << 20) - 1, (1 << 20) - 1), Tiles(8, 8)));
  EXPECT_TRUE(Has(s, "17179869184 tiles, more than 4194304")) << s.ToString();
}

// Multi-part files: every part's header is checked, up to the empty header.
TEST(ExrHeader, EveryPartOfAMultiPartFileIsChecked) {
  const std::string part0 = Attr("channels", "chlist", Channels({"R"})) + Attr("i", "int", U32(1));
  const std::string part1 = Attr("channels", "chlist", Channels({"G"}));
  EXPECT_TRUE(Check("mp", File(Magic(0x1200) + part0 + '\0' + part1 + '\0' + '\0')).ok());
  const std::string bad1 = Attr("channels", "chlist", 20, Channels({"G"}));
  Status s = Check("mp", File(Magic(0x1200) + part0 + '\0' + bad1 + '\0' + '\0'));
  EXPECT_TRUE(Has(s, "channels (chlist) in part 1 declares 20 bytes")) << s.ToString();
  // Without the multi-part flag only the first header is a header.
  EXPECT_TRUE(Check("sp", File(Magic(0x200) + part0 + '\0' + bad1 + '\0')).ok());
}

// Files OpenEXR writes pass, with every attribute type it knows, one part
// or several: the sizes above are OpenEXR's.
TEST(ExrHeader, HeadersOpenExrWritesPass) {
  const std::string path = TempPath("imf");
  Imf::Header h(8, 4);
  h.channels().insert("R", Imf::Channel(Imf::HALF));
  h.channels().insert("id", Imf::Channel(Imf::UINT));
  h.setTileDescription(Imf::TileDescription(4, 4));
  h.insert("b2f", Imf::Box2fAttribute(Imath::Box2f({0, 0}, {1, 2})));
  h.insert("chroma", Imf::ChromaticitiesAttribute(Imf::Chromaticities()));
  h.insert("d", Imf::DoubleAttribute(1.5));
  h.insert("env", Imf::EnvmapAttribute(Imf::ENVMAP_CUBE));
  h.insert("fv", Imf::FloatVectorAttribute({1.0f, 2.0f, 3.0f}));
  h.insert("i", Imf::IntAttribute(7));
  h.insert("kc", Imf::KeyCodeAttribute(Imf::KeyCode()));
  h.insert("m33f", Imf::M33fAttribute(Imath::M33f()));
  h.insert("m33d", Imf::M33dAttribute(Imath::M33d()));
  h.insert("m44f", Imf::M44fAttribute(Imath::M44f()));
  h.insert("m44d", Imf::M44dAttribute(Imath::M44d()));
  h.insert("prev", Imf::PreviewImageAttribute(Imf::PreviewImage(3, 2)));
  h.insert("rat", Imf::RationalAttribute(Imf::Rational(24, 1)));
  h.insert("s", Imf::StringAttribute("text"));
  h.insert("sv", Imf::StringVectorAttribute({"a", "", "bcd"}));
  h.insert("tc", Imf::TimeCodeAttribute(Imf::TimeCode()));
  h.insert("v2i", Imf::V2iAttribute(Imath::V2i(1, 2)));
  h.insert("v2f", Imf::V2fAttribute(Imath::V2f(1, 2)));
  h.insert("v2d", Imf::V2dAttribute(Imath::V2d(1, 2)));
  h.insert("v3i", Imf::V3iAttribute(Imath::V3i(1, 2, 3)));
  h.insert("v3f", Imf::V3fAttribute(Imath::V3f(1, 2, 3)));
  h.insert("v3d", Imf::V3dAttribute(Imath::V3d(1, 2, 3)));
  { Imf::TiledOutputFile out(path.c_str(), h); }  // no tiles: the header is what counts
  Status s = CheckExrHeaders(path);
  EXPECT_TRUE(s.ok()) << s.ToString();
  // Two parts.
  Imf::Header h2 = h;
  h.setName("left");
  h.setType(Imf::TILEDIMAGE);
  h2.setName("right");
  h2.setType(Imf::TILEDIMAGE);
  h2.insert("extra", Imf::StringAttribute(std::string(300, 'e')));
  { Imf::MultiPartOutputFile out(path.c_str(), std::vector<Imf::Header>{h, h2}.data(), 2); }
  ASSERT_NE(Bytes(path).find("extra"), std::string::npos);
  s = CheckExrHeaders(path);
  EXPECT_TRUE(s.ok()) << s.ToString();
  std::remove(path.c_str());
}

// The exr target's third finding: a part with tiles of 8 x 1032 pixels
// merged with one of 8 x 8 (the same tile width) overran vox-merge's 8 x 8
// tile buffer. vox writes square tiles; its readers refuse others.
TEST(ExrHeader, NonSquareTilesAreRefused) {
  const std::string path = TempPath("rect");
  Imf::Header h(24, 16);
  h.channels().insert("R", Imf::Channel(Imf::FLOAT));
  h.setTileDescription(Imf::TileDescription(8, 32));
  { Imf::TiledOutputFile out(path.c_str(), h); }
  EXPECT_TRUE(CheckExrHeaders(path).ok());  // a valid EXR, just not vox's
  auto info = ReadExrInfo(path);
  ASSERT_FALSE(info.ok());
  EXPECT_TRUE(Has(info.status(), path + ": tiles of 8 x 32 pixels; vox writes square tiles"))
      << info.status().ToString();
  EXPECT_FALSE(ReadExr(path).ok());
  EXPECT_FALSE(MergeParts({path}, path + ".out.exr").ok());
  std::remove(path.c_str());
}

// vox's own files, every compression it writes, still read.
TEST(ExrHeader, VoxFilesOfEveryCompressionRead) {
  for (const char* name : {"zip", "zips", "piz", "rle", "none"}) {
    const std::string path = TempPath(name);
    auto c = ParseExrCompression(name);
    ASSERT_TRUE(c.ok());
    auto w = TiledExrWriter::Create(path, 20, 10, 16, {}, {{"vox:note", name}}, *c);
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    TileBuffer buf;
    buf.Allocate(16, {});
    const TileLayout layout(20, 10, 16);
    for (const TileRect& t : layout.order()) ASSERT_TRUE((*w)->WriteTile(t, buf).ok());
    ASSERT_TRUE((*w)->Finish(1.0, R"({"render_seconds":1})").ok());
    EXPECT_TRUE(CheckExrHeaders(path).ok()) << name;
    auto img = ReadExr(path);
    ASSERT_TRUE(img.ok()) << name << ": " << img.status().ToString();
    EXPECT_EQ(img->info.compression, name);
    EXPECT_EQ(img->info.attrs["vox:note"], name);
    std::remove(path.c_str());
  }
}

}  // namespace
}  // namespace vox

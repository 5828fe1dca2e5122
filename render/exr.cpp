#include "render/exr.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfTileDescription.h>
#include <OpenEXR/ImfTiledInputFile.h>
#include <OpenEXR/ImfTiledOutputFile.h>
#include <Imath/ImathMatrix.h>
#include <Imath/half.h>
#include <fcntl.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>

#include "render/camera.h"
#include "render/internal/exr_header.h"
#include "core/util/atomic_file.h"

namespace vox {
namespace {

constexpr size_t kTimingsSlot = 1000;

const char* const kChannelNames[kNumChannels] = {
    "R",       "G",       "B",   "A",   "Z",   "N.X",     "N.Y",     "N.Z",
    "voxel.i", "voxel.j", "voxel.k", "P.X", "P.Y", "P.Z", "distance"};

Imf::Slice TileSlice(float* base, int stride) {
  return Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(base), sizeof(float),
                    sizeof(float) * size_t(stride), 1, 1, 0.0, /*xTileCoords=*/true,
                    /*yTileCoords=*/true);
}

// Adds `cam` to `header` (render/camera.h computes the values).
void AddStandardCameraAttributes(const ExrCameraAttributes& cam, Imf::Header* header) {
  const auto matrix = [](const std::array<float, 16>& m) {
    return Imath::M44f(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9], m[10], m[11],
                       m[12], m[13], m[14], m[15]);
  };
  Imf::addWorldToCamera(*header, matrix(cam.world_to_camera));
  Imf::addWorldToNDC(*header, matrix(cam.world_to_ndc));
  // The display window on the image plane: z = 1 in camera space
  // (perspective), any plane of constant z (orthographic).
  header->screenWindowCenter() = Imath::V2f(0.0f, 0.0f);
  header->screenWindowWidth() = cam.screen_window_width;
}

Imf::Slice HalfTileSlice(Imath::half* base, int stride) {
  return Imf::Slice(Imf::HALF, reinterpret_cast<char*>(base), sizeof(Imath::half),
                    sizeof(Imath::half) * size_t(stride), 1, 1, 0.0, /*xTileCoords=*/true,
                    /*yTileCoords=*/true);
}

// R, G, B, A: HALF unless the layers ask for float colour.
bool IsHalf(const ImageLayers& layers, int c) { return !layers.float_color && c <= kChA; }

struct CompressionEntry {
  const char* name;
  ExrCompression c;
  Imf::Compression imf;
};
constexpr CompressionEntry kCompressions[] = {
    {"zip", ExrCompression::kZip, Imf::ZIP_COMPRESSION},
    {"zips", ExrCompression::kZips, Imf::ZIPS_COMPRESSION},
    {"piz", ExrCompression::kPiz, Imf::PIZ_COMPRESSION},
    {"rle", ExrCompression::kRle, Imf::RLE_COMPRESSION},
    {"none", ExrCompression::kNone, Imf::NO_COMPRESSION}};

// An OpenEXR output stream over the temporary, opened without O_CREAT: once a
// signal's cleanup has removed the temporary (tools/common/signals.h),
// nothing makes it again.
class TemporaryOStream : public Imf::OStream {
 public:
  TemporaryOStream(const std::string& path, int fd) : Imf::OStream(path.c_str()), fd_(fd) {}
  ~TemporaryOStream() override { close(fd_); }
  void write(const char c[], int n) override {
    size_t done = 0;
    while (done < size_t(n)) {
      const ssize_t w = pwrite(fd_, c + done, size_t(n) - done, off_t(pos_ + done));
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) throw std::runtime_error(std::string("write failed: ") + std::strerror(errno));
      done += size_t(w);
    }
    pos_ += done;
  }
  uint64_t tellp() override { return pos_; }
  void seekp(uint64_t pos) override { pos_ = pos; }

 private:
  int fd_;
  uint64_t pos_ = 0;
};

// Opens the existing temporary `path` for writing (never creating it).
int OpenTemporary(const std::string& path) { return open(path.c_str(), O_WRONLY | O_CLOEXEC); }

}  // namespace

const char* ChannelName(int c) { return kChannelNames[c]; }

StatusOr<ExrCompression> ParseExrCompression(const std::string& name) {
  for (const CompressionEntry& e : kCompressions)
    if (name == e.name) return e.c;
  return InvalidArgumentError("EXR compression '" + name + "': expected zip, zips, piz, rle or none");
}

const char* ExrCompressionName(ExrCompression c) {
  for (const CompressionEntry& e : kCompressions)
    if (c == e.c) return e.name;
  return "?";
}

void SetExrThreads(int threads) {
  const int n = std::max(threads, 0);
  if (Imf::globalThreadCount() != n) Imf::setGlobalThreadCount(n);
}

void TileBuffer::Allocate(int tile_size, const ImageLayers& layers) {
  size = tile_size;
  for (int c = 0; c < kNumChannels; ++c) {
    if (layers.Has(c))
      ch[c].assign(size_t(tile_size) * tile_size, 0.0f);
    else
      ch[c].clear();
  }
}

TiledExrWriter::~TiledExrWriter() { Abandon(); }

StatusOr<std::unique_ptr<TiledExrWriter>> TiledExrWriter::Create(const std::string& path, int width,
                                                                 int height, int tile,
                                                                 const ImageLayers& layers,
                                                                 const ExrAttributes& attrs,
                                                                 ExrCompression compression,
                                                                 const ExrCameraAttributes* camera) {
  auto w = std::unique_ptr<TiledExrWriter>(new TiledExrWriter());
  w->path_ = path;
  w->layers_ = layers;
  VOX_ASSIGN_OR_RETURN(AtomicFile out, AtomicFile::Create(path));
  w->out_ = std::make_unique<AtomicFile>(std::move(out));
  try {
    Imf::Header header(width, height);
    header.setTileDescription(Imf::TileDescription(tile, tile, Imf::ONE_LEVEL));
    header.lineOrder() = Imf::RANDOM_Y;
    header.compression() = Imf::NO_COMPRESSION;
    for (const CompressionEntry& e : kCompressions)
      if (e.c == compression) header.compression() = e.imf;
    // Tiles are compressed under the writer's lock: zlib's fastest level
    // keeps that short (a few percent larger files than the default level).
    header.zipCompressionLevel() = 1;
    for (int c = 0; c < kNumChannels; ++c)
      if (layers.Has(c))
        header.channels().insert(kChannelNames[c],
                                 Imf::Channel(IsHalf(layers, c) ? Imf::HALF : Imf::FLOAT));
    for (const auto& [k, v] : attrs) header.insert(k, Imf::StringAttribute(v));
    if (camera != nullptr) AddStandardCameraAttributes(*camera, &header);
    header.insert("renderTimeSeconds", Imf::FloatAttribute(0.0f));
    header.insert("vox:timings", Imf::StringAttribute(std::string(kTimingsSlot, ' ')));
    const int fd = OpenTemporary(w->out_->temp_path());
    if (fd < 0)
      return IoError(path + ": cannot open the temporary " + w->out_->temp_path() + ": " +
                     std::strerror(errno));
    w->stream_ = std::make_unique<TemporaryOStream>(w->out_->temp_path(), fd);
    w->file_ = std::make_unique<Imf::TiledOutputFile>(*w->stream_, header);
  } catch (const std::bad_alloc&) {
    return ResourceExhaustedError(path + ": out of memory creating the EXR (" +
                                  std::to_string(width) + "x" + std::to_string(height) + ")");
  } catch (const std::exception& e) {
    return IoError(path + ": cannot create EXR: " + e.what());
  }
  return w;
}

Status TiledExrWriter::WriteTile(const TileRect& rect, const TileBuffer& buf) {
  // The HALF channels' pixels, converted outside the lock (one buffer per
  // thread, reused).
  thread_local std::vector<Imath::half> halves;
  const size_t n = size_t(buf.size) * size_t(buf.size);
  if (!layers_.float_color) {
    halves.resize(4 * n);
    for (int c = 0; c <= kChA; ++c) {
      const float* src = buf.ch[c].data();
      Imath::half* dst = halves.data() + size_t(c) * n;
      for (size_t i = 0; i < n; ++i) dst[i] = Imath::half(src[i]);
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (!file_) return InternalError(path_ + ": WriteTile after Finish");
  if (!failed_.ok()) return failed_;
  try {
    Imf::FrameBuffer fb;
    for (int c = 0; c < kNumChannels; ++c)
      if (layers_.Has(c))
        fb.insert(kChannelNames[c],
                  IsHalf(layers_, c)
                      ? HalfTileSlice(halves.data() + size_t(c) * n, buf.size)
                      : TileSlice(const_cast<float*>(buf.ch[c].data()), buf.size));
    file_->setFrameBuffer(fb);
    file_->writeTile(rect.tx, rect.ty);
  } catch (const std::exception& e) {
    // A TiledOutputFile whose writeTile threw cannot be used again: the
    // tile buffer it failed on is never released, so the next writeTile
    // waits for it forever. Every later call returns this error instead.
    failed_ = IoError(path_ + ": writing tile (" + std::to_string(rect.tx) + ", " +
                      std::to_string(rect.ty) + ") failed: " + e.what());
    return failed_;
  }
  return OkStatus();
}

Status TiledExrWriter::Finish(double render_seconds, const std::string& timings_json,
                              OutputGroup* group) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!file_ || !out_) return InternalError(path_ + ": EXR already finished");
  if (!failed_.ok()) {
    try {
      file_.reset();
    } catch (const std::exception&) {
    }
    stream_.reset();
    out_.reset();  // removes the temporary
    return failed_;
  }
  Status s;
  try {
    file_.reset();
  } catch (const std::exception& e) {
    s = IoError(path_ + ": closing EXR failed: " + e.what());
  }
  stream_.reset();
  if (s.ok()) {
    s = PatchTimings(out_->temp_path(), render_seconds, timings_json);
    if (!s.ok()) s = s.WithContext(path_);
  }
  if (s.ok() && group != nullptr) {
    group->AddFile(std::move(*out_));
  } else if (s.ok()) {
    s = out_->Commit();
  }
  out_.reset();  // removes the temporary unless committed or handed over
  return s;
}

void TiledExrWriter::Abandon() {
  std::lock_guard<std::mutex> lock(mu_);
  try {
    file_.reset();
  } catch (const std::exception&) {
  }
  stream_.reset();
  out_.reset();
}

namespace {

// The header attributes of a single-part EXR: magic, version, then
// (name NUL, type NUL, int32 size, value) until an empty name. Finds the
// offset of the value of `name` with type `type` and `size` bytes.
Status FindAttributeValue(std::istream& f, const std::string& path,
                          const std::map<std::string, std::pair<std::string, uint32_t>>& wanted,
                          std::map<std::string, uint64_t>* found) {
  f.seekg(0, std::ios::end);
  const uint64_t file_size = uint64_t(f.tellg());
  f.seekg(8);
  auto read_cstr = [&](std::string* out) -> bool {
    out->clear();
    for (;;) {
      int c = f.get();
      if (c == EOF) return false;
      if (c == 0) return true;
      if (out->size() > 255) return false;  // EXR names are at most 255 bytes
      out->push_back(char(c));
    }
  };
  std::string name, type;
  for (;;) {
    if (!read_cstr(&name)) return CorruptionError(path + ": truncated EXR header");
    if (name.empty()) break;
    if (!read_cstr(&type)) return CorruptionError(path + ": truncated EXR header");
    uint8_t sz[4];
    if (!f.read(reinterpret_cast<char*>(sz), 4))
      return CorruptionError(path + ": truncated EXR header");
    const uint32_t size =
        uint32_t(sz[0]) | uint32_t(sz[1]) << 8 | uint32_t(sz[2]) << 16 | uint32_t(sz[3]) << 24;
    const uint64_t at = uint64_t(f.tellg());
    if (at + size > file_size)  // before OpenEXR allocates what the size claims
      return CorruptionError(path + ": EXR header attribute " + name + " claims " +
                             std::to_string(size) + " bytes, more than the file holds");
    auto it = wanted.find(name);
    if (it != wanted.end() && it->second.first == type) {
      if (it->second.second != size)
        return CorruptionError(path + ": header slot " + name + " has the wrong size");
      (*found)[name] = at;
    }
    f.seekg(std::streamoff(at + size));
    if (!f) return CorruptionError(path + ": truncated EXR header");
  }
  for (const auto& [k, v] : wanted)
    if (!found->count(k)) return CorruptionError(path + ": header slot " + k + " not found");
  return OkStatus();
}

}  // namespace

Status PatchTimings(const std::string& path, double render_seconds,
                    const std::string& timings_json) {
  if (timings_json.size() > kTimingsSlot)
    return InternalError("timings JSON longer than its header slot");
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  if (!f) return IoError(path + ": cannot reopen to record timings");
  std::map<std::string, uint64_t> at;
  VOX_RETURN_IF_ERROR(FindAttributeValue(
      f, path,
      {{"renderTimeSeconds", {"float", 4}}, {"vox:timings", {"string", uint32_t(kTimingsSlot)}}},
      &at));
  f.clear();
  float secs = float(render_seconds);
  f.seekp(std::streamoff(at["renderTimeSeconds"]));
  f.write(reinterpret_cast<const char*>(&secs), 4);  // little-endian (x86, EXR)
  std::string padded = timings_json + std::string(kTimingsSlot - timings_json.size(), ' ');
  f.seekp(std::streamoff(at["vox:timings"]));
  f.write(padded.data(), std::streamsize(padded.size()));
  f.flush();
  if (!f) return IoError(path + ": writing timings failed");
  return OkStatus();
}

namespace {

ExrInfo InfoFromFile(const Imf::TiledInputFile& in) {
  ExrInfo info;
  const Imf::Header& h = in.header();
  const auto& dw = h.dataWindow();
  info.width = dw.max.x - dw.min.x + 1;
  info.height = dw.max.y - dw.min.y + 1;
  info.tile = int(in.tileXSize());
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
    info.channels.push_back(it.name());
    if (std::strcmp(it.name(), "R") == 0) info.float_color = it.channel().type == Imf::FLOAT;
  }
  info.compression = "?";
  for (const CompressionEntry& e : kCompressions)
    if (e.imf == h.compression()) info.compression = e.name;
  for (auto it = h.begin(); it != h.end(); ++it) {
    if (auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
      info.attrs[it.name()] = s->value();
    if (std::strcmp(it.name(), "renderTimeSeconds") == 0)
      if (auto* f = dynamic_cast<const Imf::FloatAttribute*>(&it.attribute()))
        info.render_seconds = f->value();
  }
  info.complete = in.isComplete();
  return info;
}

// vox writes square tiles, and its readers (vox-merge's tile buffers) size
// them by ExrInfo::tile: a file with other tiles is not vox's.
Status CheckSquareTiles(const Imf::TiledInputFile& in, const std::string& path) {
  if (in.tileXSize() != in.tileYSize())
    return CorruptionError(path + ": tiles of " + std::to_string(in.tileXSize()) + " x " +
                           std::to_string(in.tileYSize()) +
                           " pixels; vox writes square tiles");
  return OkStatus();
}

}  // namespace

StatusOr<ExrInfo> ReadExrInfo(const std::string& path) {
  VOX_RETURN_IF_ERROR(CheckExrHeaders(path));
  try {
    Imf::TiledInputFile in(path.c_str());
    VOX_RETURN_IF_ERROR(CheckSquareTiles(in, path));
    return InfoFromFile(in);
  } catch (const std::exception& e) {
    return IoError(path + ": cannot read as a tiled EXR: " + e.what());
  }
}

StatusOr<ExrImage> ReadExr(const std::string& path) {
  VOX_RETURN_IF_ERROR(CheckExrHeaders(path));
  try {
    Imf::TiledInputFile in(path.c_str());
    VOX_RETURN_IF_ERROR(CheckSquareTiles(in, path));
    ExrImage img;
    img.info = InfoFromFile(in);
    if (!img.info.complete)
      return CorruptionError(path + ": EXR is missing tiles (a partial render?)");
    const auto& dw = in.header().dataWindow();
    Imf::FrameBuffer fb;
    const size_t w = size_t(img.info.width), h = size_t(img.info.height);
    for (const std::string& c : img.info.channels) {
      auto& v = img.pixels[c];
      v.assign(w * h, 0.0f);
      char* base =
          reinterpret_cast<char*>(v.data()) -
          (ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y) * ptrdiff_t(w)) * ptrdiff_t(sizeof(float));
      fb.insert(c, Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * w));
    }
    in.setFrameBuffer(fb);
    in.readTiles(0, in.numXTiles() - 1, 0, in.numYTiles() - 1);
    return img;
  } catch (const std::exception& e) {
    return IoError(path + ": cannot read EXR: " + e.what());
  }
}

Status VerifyExrTiles(const std::string& path) {
  VOX_RETURN_IF_ERROR(CheckExrHeaders(path));
  try {
    Imf::TiledInputFile in(path.c_str());
    VOX_RETURN_IF_ERROR(CheckSquareTiles(in, path));
    if (!in.isComplete())
      return CorruptionError(path + ": EXR is missing tiles (a partial render?)");
    const auto& dw = in.header().dataWindow();
    const std::string channel = in.header().channels().begin().name();
    const size_t w = size_t(dw.max.x - dw.min.x + 1), tile = size_t(in.tileYSize());
    std::vector<float> row(w * tile);
    for (int ty = 0; ty < in.numYTiles(); ++ty) {
      const ptrdiff_t y0 = ptrdiff_t(dw.min.y) + ptrdiff_t(ty) * ptrdiff_t(tile);
      char* base = reinterpret_cast<char*>(row.data()) -
                   (ptrdiff_t(dw.min.x) + y0 * ptrdiff_t(w)) * ptrdiff_t(sizeof(float));
      Imf::FrameBuffer fb;
      fb.insert(channel, Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * w));
      in.setFrameBuffer(fb);
      in.readTiles(0, in.numXTiles() - 1, ty, ty);
    }
    return OkStatus();
  } catch (const std::exception& e) {
    return IoError(path + ": cannot read EXR: " + e.what());
  }
}

namespace {

uint8_t ToSrgb8(float v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(double(v), 1 / 2.4) - 0.055;
  return uint8_t(std::lround(s * 255.0));
}

struct PngFile {
  FILE* fp = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  ~PngFile() {
    if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
    if (fp) fclose(fp);
  }
};

// libpng reports an error by longjmp to the last setjmp. Every call into it
// goes through these functions, whose frames hold no object with a
// destructor (the jump would skip it): each returns false after a jump.
[[gnu::noinline]] bool PngStart(const PngFile& out, int width, int height) {
  if (setjmp(png_jmpbuf(out.png))) return false;
  png_init_io(out.png, out.fp);
  png_set_IHDR(out.png, out.info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(out.png, out.info);
  return true;
}
[[gnu::noinline]] bool PngWriteRow(const PngFile& out, const uint8_t* row) {
  if (setjmp(png_jmpbuf(out.png))) return false;
  png_write_row(out.png, row);
  return true;
}
[[gnu::noinline]] bool PngFinish(const PngFile& out) {
  if (setjmp(png_jmpbuf(out.png))) return false;
  png_write_end(out.png, nullptr);
  return true;
}

}  // namespace

Status WritePngPreview(const std::string& exr_path, const std::string& png_path,
                       const PreviewBackground& background, OutputGroup* group,
                       const std::string& exr_read_path) {
  const std::string& read_path = exr_read_path.empty() ? exr_path : exr_read_path;
  VOX_RETURN_IF_ERROR(CheckExrHeaders(read_path));
  try {
    Imf::TiledInputFile in(read_path.c_str());
    ExrInfo info = InfoFromFile(in);
    if (!info.complete)
      return InvalidArgumentError(exr_path +
                                  ": a partial EXR has no preview; merge the parts first");
    const auto& dw = in.header().dataWindow();
    const int w = info.width, tile = int(in.tileYSize());
    std::vector<float> band[4];  // R G B, and A to compose over `background`
    for (auto& b : band) b.assign(size_t(w) * tile, 0.0f);
    std::vector<uint8_t> row(size_t(w) * 3);

    VOX_ASSIGN_OR_RETURN(AtomicFile atomic, AtomicFile::Create(png_path));
    PngFile out;
    const int fd = OpenTemporary(atomic.temp_path());
    out.fp = fd >= 0 ? fdopen(fd, "wb") : nullptr;
    if (!out.fp) {
      if (fd >= 0) close(fd);
      return IoError(png_path + ": cannot open for writing");
    }
    out.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    if (!out.png) return ResourceExhaustedError(png_path + ": libpng init failed");
    out.info = png_create_info_struct(out.png);
    if (!out.info) return ResourceExhaustedError(png_path + ": libpng init failed");
    const Status png_failed = IoError(png_path + ": libpng write failed");
    if (!PngStart(out, w, info.height)) return png_failed;
    const char* names[4] = {"R", "G", "B", "A"};
    const int read_channels = background ? 4 : 3;
    for (int ty = 0; ty < in.numYTiles(); ++ty) {
      const int y0 = ty * tile;
      const int rows = std::min(tile, info.height - y0);
      Imf::FrameBuffer fb;
      for (int c = 0; c < read_channels; ++c) {
        char* base = reinterpret_cast<char*>(band[c].data()) -
                     (ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y + y0) * ptrdiff_t(w)) *
                         ptrdiff_t(sizeof(float));
        fb.insert(names[c], Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * size_t(w)));
      }
      in.setFrameBuffer(fb);
      in.readTiles(0, in.numXTiles() - 1, ty, ty);
      for (int y = 0; y < rows; ++y) {
        for (int x = 0; x < w; ++x) {
          const size_t p = size_t(y) * w + x;
          float bg[3] = {0.0f, 0.0f, 0.0f};
          if (background) background(x, y0 + y, bg);
          const float behind = background ? 1.0f - band[3][p] : 0.0f;
          for (int c = 0; c < 3; ++c)
            row[size_t(x) * 3 + c] = ToSrgb8(band[c][p] + behind * bg[c]);
        }
        if (!PngWriteRow(out, row.data())) return png_failed;
      }
    }
    if (!PngFinish(out)) return png_failed;
    const bool flushed = fflush(out.fp) == 0;
    const bool closed = fclose(out.fp) == 0;
    out.fp = nullptr;
    if (!flushed || !closed) return IoError(png_path + ": write failed");
    if (group == nullptr) return atomic.Commit();
    group->AddFile(std::move(atomic));
    return OkStatus();
  } catch (const std::exception& e) {
    return IoError(exr_path + ": cannot read EXR for the preview: " + e.what());
  }
}

}  // namespace vox

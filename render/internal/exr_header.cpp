#include "render/internal/exr_header.h"

#include <OpenEXR/OpenEXRConfig.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>

#include "render/limits.h"

namespace vox {
namespace {

// The layout (docs/robustness.md, and OpenEXR's "OpenEXR File Layout"):
// magic (4 bytes), version (4: the format version 2 in the low byte, flags
// above), then a header: attributes (name NUL, type name NUL, int32 size,
// value) until an empty name. A multi-part file has one such header per
// part and ends the list with an empty header. All numbers little-endian.
constexpr uint32_t kMultiPartFlag = 0x1000;
constexpr size_t kMaxNameLength = 255;  // OpenEXR's Name::MAX_LENGTH

// Values of a fixed size that OpenEXR reads whatever size the attribute
// declares (Imf*Attribute.cpp, readValueFrom).
const std::map<std::string, uint32_t>& FixedSizes() {
  static const auto* sizes = new std::map<std::string, uint32_t>{
      {"box2i", 16},      {"box2f", 16},         {"compression", 1},   {"chromaticities", 32},
      {"deepImageState", 1}, {"double", 8},      {"envmap", 1},        {"float", 4},
      {"int", 4},         {"keycode", 28},       {"lineOrder", 1},     {"m33f", 36},
      {"m33d", 72},       {"m44f", 64},          {"m44d", 128},        {"rational", 8},
      {"tiledesc", 9},    {"timecode", 8},       {"v2i", 8},           {"v2f", 8},
      {"v2d", 16},        {"v3i", 12},           {"v3f", 12},          {"v3d", 24}};
  return *sizes;
}

class Reader {
 public:
  Reader(std::istream& in, uint64_t size) : in_(in), size_(size) {}
  uint64_t pos() const { return pos_; }
  uint64_t left() const { return size_ - pos_; }
  bool Read(void* out, size_t n) {
    if (n > left() || !in_.read(static_cast<char*>(out), std::streamsize(n))) return false;
    pos_ += n;
    return true;
  }
  bool U32(uint32_t* v) {
    uint8_t b[4];
    if (!Read(b, 4)) return false;
    *v = uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
    return true;
  }
  bool Skip(uint64_t n) {
    if (n > left()) return false;
    in_.seekg(std::streamoff(pos_ + n));
    pos_ += n;
    return bool(in_);
  }
  // A NUL-terminated name of at most kMaxNameLength bytes. 0: read, 1: end
  // of file, 2: no NUL within the limit.
  int Name(std::string* out) {
    out->clear();
    for (;;) {
      char c;
      if (!Read(&c, 1)) return 1;
      if (c == 0) return 0;
      if (out->size() == kMaxNameLength) return 2;
      out->push_back(c);
    }
  }

 private:
  std::istream& in_;
  const uint64_t size_;
  uint64_t pos_ = 0;
};

// Parses the value of a variable-size type OpenEXR reads by its own layout
// and returns the bytes that reading consumes, or an error naming the flaw.
// Stops early, returning more than `size`, once the value runs past it.
StatusOr<uint64_t> ParsedSize(Reader& r, const std::string& type, uint32_t size,
                              const std::string& where) {
  const std::string truncated = where + " runs past the end of the file";
  if (type == "chlist") {  // (name NUL, int32 type, uint8 pLinear, 3 reserved, 2 int32)* NUL
    uint64_t used = 0;
    std::string name;
    for (;;) {
      const int got = r.Name(&name);
      if (got == 1) return CorruptionError(truncated);
      if (got == 2) return CorruptionError(where + ": a channel name is longer than 255 bytes");
      used += name.size() + 1;
      if (name.empty()) return used;
      uint32_t pixel_type;
      if (!r.U32(&pixel_type) || !r.Skip(12)) return CorruptionError(truncated);
      if (pixel_type > 2)  // UINT, HALF, FLOAT
        return CorruptionError(where + ": channel " + name + " has the unknown pixel type " +
                               std::to_string(pixel_type));
      used += 16;
      if (used > size) return used;
    }
  }
  if (type == "stringvector") {  // (int32 length, bytes)* filling the size exactly
    uint64_t used = 0;
    while (used < size) {
      uint32_t len;
      if (size - used < 4) return used + 4;  // OpenEXR would read the length past the value
      if (!r.U32(&len)) return CorruptionError(truncated);
      used += 4;
      if (len > size - used)
        return CorruptionError(where + ": a string of " + std::to_string(len) +
                               " bytes runs past the attribute's declared " +
                               std::to_string(size));
      if (!r.Skip(len)) return CorruptionError(truncated);
      used += len;
    }
    return used;
  }
  if (type == "preview") {  // uint32 width, height, then 4 bytes a pixel
    uint32_t w, h;
    if (size < 8) return uint64_t(8);
    if (!r.U32(&w) || !r.U32(&h)) return CorruptionError(truncated);
    if (w > uint32_t(INT32_MAX) || h > uint32_t(INT32_MAX))
      return CorruptionError(where + ": negative preview size");
    const uint64_t used = 8 + uint64_t(w) * h * 4;
    if (used <= size && !r.Skip(used - 8)) return CorruptionError(truncated);
    return used;
  }
  if (type == "floatvector") {  // OpenEXR reads size / 4 floats
    if (!r.Skip(size)) return CorruptionError(truncated);
    return uint64_t(size / 4 * 4);
  }
  if (type == "idmanifest") {  // uint64 uncompressed size, then the compressed bytes
#if OPENEXR_VERSION_MAJOR > 3 || (OPENEXR_VERSION_MAJOR == 3 && OPENEXR_VERSION_MINOR >= 2)
    if (size < 8) return uint64_t(8);
    if (!r.Skip(size)) return CorruptionError(truncated);
    return uint64_t(size);
#else
    // OpenEXR before 3.2 reads 8 + (size - 4) bytes: four more than declared.
    return CorruptionError(where + ": idmanifest attributes are misread by this OpenEXR (" +
                           OPENEXR_VERSION_STRING + ")");
#endif
  }
  // string, and types OpenEXR does not know (kept as opaque bytes): the
  // declared size is what is read.
  if (!r.Skip(size)) return CorruptionError(truncated);
  return uint64_t(size);
}

int32_t I32(const char* p) {
  return int32_t(uint32_t(uint8_t(p[0])) | uint32_t(uint8_t(p[1])) << 8 |
                 uint32_t(uint8_t(p[2])) << 16 | uint32_t(uint8_t(p[3])) << 24);
}

// The image geometry of one header, as far as it was found.
struct Geometry {
  bool has_window = false, has_tiles = false;
  int64_t width = 0, height = 0;
  uint32_t tile_x = 0, tile_y = 0;
};

// OpenEXR allocates by the tile description and the data window (a tile's
// buffer, the table of tile offsets) before reading any pixel: values beyond
// what vox writes are refused here (the limits of render/limits.h).
Status CheckGeometry(const Geometry& g, const std::string& path, const std::string& part) {
  const std::string where = path + ": EXR header" + part + ": ";
  if (g.has_tiles && (g.tile_x < 1 || g.tile_y < 1 || g.tile_x > uint32_t(kMaxTileSize) ||
                      g.tile_y > uint32_t(kMaxTileSize)))
    return CorruptionError(where + "tiles of " + std::to_string(g.tile_x) + " x " +
                           std::to_string(g.tile_y) + " pixels (vox writes at most " +
                           std::to_string(kMaxTileSize) + " a side)");
  if (g.has_window && (g.width < 1 || g.height < 1 || g.width > kMaxImageSide ||
                       g.height > kMaxImageSide))
    return CorruptionError(where + "data window of " + std::to_string(g.width) + " x " +
                           std::to_string(g.height) + " pixels (at most " +
                           std::to_string(kMaxImageSide) + " a side)");
  if (g.has_tiles && g.has_window) {
    const int64_t tiles = (g.width + g.tile_x - 1) / g.tile_x * ((g.height + g.tile_y - 1) / g.tile_y);
    if (tiles > kMaxTiles)
      return CorruptionError(where + std::to_string(tiles) + " tiles, more than " +
                             std::to_string(kMaxTiles));
  }
  return OkStatus();
}

// One header; *attributes counts its attributes (0: the empty header that
// ends a multi-part file's list).
Status CheckHeader(Reader& r, const std::string& path, const std::string& part,
                   int* attributes) {
  *attributes = 0;
  Geometry geometry;
  const std::string truncated = path + ": EXR header truncated" + part;
  std::string name, type;
  for (;;) {
    int got = r.Name(&name);
    if (got == 1) return CorruptionError(truncated);
    if (got == 2)
      return CorruptionError(path + ": EXR header attribute name longer than 255 bytes" + part);
    if (name.empty()) return CheckGeometry(geometry, path, part);
    ++*attributes;
    got = r.Name(&type);
    if (got == 1) return CorruptionError(truncated);
    const std::string where = path + ": EXR header attribute " + name + " (" +
                              (got == 2 ? type.substr(0, 32) + "..." : type) + ")" + part;
    if (got == 2) return CorruptionError(where + ": type name longer than 255 bytes");
    uint32_t size;
    if (!r.U32(&size)) return CorruptionError(truncated);
    if (size > uint32_t(INT32_MAX))
      return CorruptionError(where + ": negative size " + std::to_string(int32_t(size)));
    if (size > r.left())  // before OpenEXR allocates what the size claims
      return CorruptionError(where + " claims " + std::to_string(size) +
                             " bytes, more than the file holds");
    const uint64_t start = r.pos();
    uint64_t parsed;
    auto fixed = FixedSizes().find(type);
    if (fixed != FixedSizes().end()) {
      parsed = fixed->second;
      char v[128];  // the largest fixed size (m44d)
      if (parsed == size && !r.Read(v, size)) return CorruptionError(truncated);
      if (parsed == size && name == "tiles" && type == "tiledesc") {
        geometry.has_tiles = true;
        geometry.tile_x = uint32_t(I32(v));
        geometry.tile_y = uint32_t(I32(v + 4));
      }
      if (parsed == size && name == "dataWindow" && type == "box2i") {
        geometry.has_window = true;
        geometry.width = int64_t(I32(v + 8)) - I32(v) + 1;
        geometry.height = int64_t(I32(v + 12)) - I32(v + 4) + 1;
      }
    } else {
      auto p = ParsedSize(r, type, size, where);
      if (!p.ok()) return p.status();
      parsed = *p;
    }
    if (parsed != size)
      return CorruptionError(where + " declares " + std::to_string(size) +
                             " bytes but its value holds " +
                             (parsed > size ? "more" : std::to_string(parsed)));
    if (r.pos() != start + size) return CorruptionError(truncated);
  }
}

}  // namespace

Status CheckExrHeaders(const std::string& path) {
  // Opening a FIFO would wait for a writer: only regular files are read.
  struct stat st;
  if (stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
    return InvalidArgumentError(path + ": not a regular file (" +
                                (S_ISFIFO(st.st_mode)  ? "a FIFO"
                                 : S_ISDIR(st.st_mode) ? "a directory"
                                                       : "a device or socket") +
                                "): EXRs are read from regular files");
  std::ifstream f(path, std::ios::binary);
  if (!f) return IoError(path + ": cannot open: " + std::strerror(errno));
  f.seekg(0, std::ios::end);
  const auto end = f.tellg();
  if (end < 0) return IoError(path + ": cannot read: " + std::strerror(errno));
  f.seekg(0);
  Reader r(f, uint64_t(end));
  char magic[4];
  if (!r.Read(magic, 4) || std::memcmp(magic, "\x76\x2f\x31\x01", 4) != 0) return OkStatus();
  uint32_t version;
  if (!r.U32(&version)) return CorruptionError(path + ": EXR header truncated");
  int attributes = 0;
  if (!(version & kMultiPartFlag)) return CheckHeader(r, path, "", &attributes);
  for (int part = 0;; ++part) {
    VOX_RETURN_IF_ERROR(CheckHeader(r, path, " in part " + std::to_string(part), &attributes));
    if (attributes == 0) return OkStatus();
  }
}

}  // namespace vox

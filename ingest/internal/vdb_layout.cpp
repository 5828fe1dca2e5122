// The .vdb layout parser. See vdb_layout.h.
#include "ingest/internal/vdb_layout.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include <openvdb/openvdb.h>

namespace vox::ingest_internal {
namespace {

std::string Quote(const std::string& s) { return "'" + s + "'"; }

// A descriptor's unique name: the grid name, with a "\x1e<n>" suffix when not unique.
std::string GridDescriptorName(const std::string& unique) {
  return unique.substr(0, unique.find('\x1e'));
}

class LayoutReader {
 public:
  LayoutReader(std::FILE* f, uint64_t size, const std::string& path)
      : f_(f), size_(size), path_(path) {}

  Status Read(void* p, uint64_t n, const char* what) {
    if (pos_ + n > size_ || std::fread(p, 1, n, f_) != n)
      return Truncated(what);
    pos_ += n;
    return OkStatus();
  }
  Status Skip(uint64_t n, const char* what) {
    if (n > size_ - pos_) return Truncated(what);
    return Seek(pos_ + n, what);
  }
  Status Seek(uint64_t p, const char* what) {
    if (p > size_) return Truncated(what);
    if (std::fseek(f_, long(p), SEEK_SET) != 0) return IoError(path_ + ": " + std::strerror(errno));
    pos_ = p;
    return OkStatus();
  }
  // A length-prefixed string (uint32 length + bytes).
  Status String(std::string* s, const char* what) {
    uint32_t n = 0;
    VOX_RETURN_IF_ERROR(Read(&n, 4, what));
    if (n > size_ - pos_) return Truncated(what);
    s->resize(n);
    return Read(s->data(), n, what);
  }
  Status Truncated(const char* what) const {
    return CorruptionError(path_ + ": truncated or corrupt VDB file: " + what + " at byte " +
                           std::to_string(pos_) + " runs past the end of the file (" +
                           std::to_string(size_) + " bytes)");
  }
  uint64_t pos() const { return pos_; }
  uint64_t size() const { return size_; }

 private:
  std::FILE* f_;
  uint64_t size_;
  const std::string& path_;
  uint64_t pos_ = 0;
};

}  // namespace

Status CheckVdbLayout(const std::string& path) { return ReadVdbLayout(path).status(); }

StatusOr<VdbLayout> ReadVdbLayout(const std::string& path) {
  VdbLayout layout;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return IoError(path + ": " + std::strerror(errno));
  struct Closer {
    std::FILE* f;
    ~Closer() { std::fclose(f); }
  } closer{f};
  struct stat st;
  if (::fstat(fileno(f), &st) != 0) return IoError(path + ": " + std::strerror(errno));
  LayoutReader r(f, uint64_t(st.st_size), path);
  int64_t magic = 0;
  if (uint64_t(st.st_size) < 8 || !r.Read(&magic, 8, "magic").ok() ||
      magic != int64_t(openvdb::OPENVDB_MAGIC))
    return CorruptionError(path + ": not a readable OpenVDB file (no VDB magic number)");
  uint32_t version = 0;
  VOX_RETURN_IF_ERROR(r.Read(&version, 4, "file version"));
  if (version < 211) {
    VOX_RETURN_IF_ERROR(r.Skip(8, "file version"));
    layout.file_version = version;
    return layout;  // pre-2.1.1 files: left to OpenVDB
  }
  layout.file_version = version;
  VOX_RETURN_IF_ERROR(r.Read(&layout.library_major, 4, "library version"));
  VOX_RETURN_IF_ERROR(r.Read(&layout.library_minor, 4, "library version"));
  char has_offsets = 1;
  if (version >= 212) VOX_RETURN_IF_ERROR(r.Read(&has_offsets, 1, "grid offsets flag"));
  if (version >= 220 && version < 222) VOX_RETURN_IF_ERROR(r.Skip(1, "compression flag"));
  VOX_RETURN_IF_ERROR(r.Skip(version >= 218 ? 36 : 16, "file UUID"));
  // File metadata: count, then (name, type name, size-prefixed value).
  int32_t count = 0;
  VOX_RETURN_IF_ERROR(r.Read(&count, 4, "file metadata count"));
  if (count < 0 || uint64_t(count) > r.size()) return r.Truncated("file metadata count");
  std::string s;
  for (int32_t i = 0; i < count; ++i) {
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata name"));
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata type"));
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata value"));
  }
  if (!has_offsets) return layout;
  layout.has_offsets = true;  // a stream without offsets: left to OpenVDB
  int32_t grids = 0;
  VOX_RETURN_IF_ERROR(r.Read(&grids, 4, "grid count"));
  if (grids < 0 || uint64_t(grids) > r.size()) return r.Truncated("grid count");
  for (int32_t g = 0; g < grids; ++g) {
    std::string name;
    VOX_RETURN_IF_ERROR(r.String(&name, "grid name"));
    VOX_RETURN_IF_ERROR(r.String(&s, "grid type"));
    VdbLayout::Grid grid;
    grid.name = GridDescriptorName(name);
    if (version >= 216) {
      VOX_RETURN_IF_ERROR(r.String(&s, "instance parent name"));
      grid.instance = !s.empty();
    }
    int64_t pos[3];
    VOX_RETURN_IF_ERROR(r.Read(pos, sizeof pos, "grid offsets"));
    if (pos[0] < int64_t(r.pos()) || pos[1] < pos[0] || pos[2] < pos[1] ||
        uint64_t(pos[2]) > r.size())
      return CorruptionError(path + ": truncated or corrupt VDB file: grid " +
                             Quote(GridDescriptorName(name)) + " spans bytes " +
                             std::to_string(pos[0]) + ".." + std::to_string(pos[2]) +
                             " of a " + std::to_string(r.size()) + "-byte file");
    grid.grid_pos = uint64_t(pos[0]);
    grid.block_pos = uint64_t(pos[1]);
    grid.end_pos = uint64_t(pos[2]);
    layout.grids.push_back(grid);
    VOX_RETURN_IF_ERROR(r.Seek(uint64_t(pos[2]), "next grid descriptor"));
  }
  return layout;
}

}  // namespace vox::ingest_internal

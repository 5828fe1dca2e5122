// The streaming topology reader. See vdb_topology.h.
#include "ingest/internal/vdb_topology.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cstring>
#include <istream>
#include <streambuf>

#include <openvdb/io/Compression.h>
#include <openvdb/io/io.h>

namespace vox::ingest_internal {
namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

// OpenVDB's bloscFromStream and unzipFromStream read a chunk stored
// uncompressed (a negative size) into the caller's buffer before comparing
// its size with the buffer's: a corrupt size overflows the buffer (found by
// fuzzing). This reads ahead what io::readCompressedValues(is, buf, count,
// value_mask, half) will read, up to the chunk's size, and throws IoError
// when the chunk would not fit: an uncompressed one of another size than
// the values need, or a compressed one longer than the rest of the stream.
// The stream is left where it was. (Files of format >= 222 only, as read
// here: each value array starts with its metadata byte.)
template <class ValueT, class MaskT>
void CheckValueChunk(std::istream& is, openvdb::Index count, const MaskT& value_mask, bool half) {
  namespace io = openvdb::io;
  const uint32_t compression = io::getDataCompression(is);
  if (!(compression & (io::COMPRESS_BLOSC | io::COMPRESS_ZIP))) return;  // read as it is
  const std::streampos start = is.tellg();
  int8_t metadata = io::NO_MASK_AND_ALL_VALS;
  is.read(reinterpret_cast<char*>(&metadata), 1);
  if (metadata == io::NO_MASK_AND_ONE_INACTIVE_VAL || metadata == io::MASK_AND_ONE_INACTIVE_VAL)
    is.seekg(std::streamoff(sizeof(ValueT)), std::ios_base::cur);
  if (metadata == io::MASK_AND_TWO_INACTIVE_VALS)
    is.seekg(std::streamoff(2 * sizeof(ValueT)), std::ios_base::cur);
  if (metadata == io::MASK_AND_NO_INACTIVE_VALS || metadata == io::MASK_AND_ONE_INACTIVE_VAL ||
      metadata == io::MASK_AND_TWO_INACTIVE_VALS) {
    MaskT selection;
    selection.load(is);
  }
  openvdb::Index stored = count;
  if ((compression & io::COMPRESS_ACTIVE_MASK) && metadata != io::NO_MASK_AND_ALL_VALS)
    stored = value_mask.countOn();
  if (half && stored == 0) {  // OpenVDB's half reader reads no chunk for no values
    is.seekg(start);
    return;
  }
  const uint64_t want = uint64_t(stored) * (half ? 2 : sizeof(ValueT));
  int64_t chunk = 0;
  is.read(reinterpret_cast<char*>(&chunk), 8);
  if (!is.good()) {  // truncated: OpenVDB's reader fails on it without writing
    is.clear();
    is.seekg(start);
    return;
  }
  const std::streampos here = is.tellg();
  is.seekg(0, std::ios_base::end);
  const uint64_t left = uint64_t(is.tellg() - here);
  is.seekg(start);
  if (chunk <= 0 ? uint64_t(0) - uint64_t(chunk) != want : uint64_t(chunk) > left)
    throw openvdb::IoError(
        "corrupt value chunk at byte " + std::to_string(uint64_t(here) - 8) + ": " +
        (chunk <= 0 ? "stored uncompressed as " + std::to_string(uint64_t(0) - uint64_t(chunk)) +
                          " bytes where its " + std::to_string(stored) + " values take " +
                          std::to_string(want)
                    : std::to_string(chunk) + " compressed bytes where the file has " +
                          std::to_string(left) + " left"));
}

// Bytes [base, base + size) of the file, held at `data`, as a seekable
// stream whose positions are file offsets.
class MemoryBuf : public std::streambuf {
 public:
  MemoryBuf(const char* data, uint64_t size, uint64_t base) : base_(base), size_(size) {
    char* p = const_cast<char*>(data);
    setg(p, p, p + size);
  }

 protected:
  pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override {
    int64_t target;
    if (dir == std::ios_base::beg)
      target = int64_t(off) - int64_t(base_);
    else if (dir == std::ios_base::cur)
      target = int64_t(gptr() - eback()) + int64_t(off);
    else
      target = int64_t(size_) + int64_t(off);
    if (target < 0 || uint64_t(target) > size_) return pos_type(off_type(-1));
    setg(eback(), eback() + target, egptr());
    return pos_type(off_type(base_ + uint64_t(target)));
  }
  pos_type seekpos(pos_type p, std::ios_base::openmode m) override {
    return seekoff(off_type(p), std::ios_base::beg, m);
  }

 private:
  uint64_t base_, size_;
};

constexpr int kRootLog2 = 12;  // a root child spans 4096^3 voxels

uint64_t RootKey(const Coord& c) {
  const uint64_t m = (uint64_t(1) << 21) - 1;
  return (uint64_t(c.x() >> kRootLog2) & m) | ((uint64_t(c.y() >> kRootLog2) & m) << 21) |
         ((uint64_t(c.z() >> kRootLog2) & m) << 42);
}

}  // namespace

template <class ValueT>
struct CompactTopology<ValueT>::Node {
  uint32_t first_child = 0;      // index of its first child in the next level down
  std::vector<uint64_t> child;   // child mask words
  std::vector<uint32_t> prefix;  // children before each word
  std::vector<ValueT> palette;   // distinct tile values (all values when bits == 0xff)
  std::vector<uint8_t> packed;   // per entry, `bits` wide: index into palette
  uint8_t bits = 0;

  bool IsChild(uint32_t n) const { return (child[n >> 6] >> (n & 63)) & 1; }
  uint32_t Rank(uint32_t n) const {
    const uint64_t below = (n & 63) ? child[n >> 6] & ((uint64_t(1) << (n & 63)) - 1) : 0;
    return first_child + prefix[n >> 6] + uint32_t(std::popcount(below));
  }
  ValueT Tile(uint32_t n) const {
    if (bits == 0) return palette.empty() ? ValueT{} : palette[0];
    if (bits == 0xff) return palette[n];
    const uint32_t bit = n * bits;
    return palette[(packed[bit >> 3] >> (bit & 7)) & ((1u << bits) - 1)];
  }
  uint64_t Bytes() const {
    return sizeof(Node) + child.capacity() * 8 + prefix.capacity() * 4 +
           palette.capacity() * sizeof(ValueT) + packed.capacity();
  }
};

template <class ValueT>
class CompactTopology<ValueT>::Parser {
 public:
  Parser(CompactTopology& t, std::istream& is, uint64_t file_size)
      : t_(t), is_(is), file_size_(file_size) {}

  // An internal node of level `level` (2: 32^3 children, 1: 16^3) at `origin`.
  template <int kLog2, int kChildTotal>
  void Internal(const Coord& origin) {
    using NodeMask = openvdb::util::NodeMask<kLog2>;
    constexpr uint32_t kNum = NodeMask::SIZE;
    NodeMask child_mask, value_mask;
    child_mask.load(is_);
    value_mask.load(is_);
    std::unique_ptr<ValueT[]> values(new ValueT[kNum]);
    CheckValueChunk<ValueT>(is_, kNum, value_mask, t_.half_);
    openvdb::io::readCompressedValues(is_, values.get(), kNum, value_mask, t_.half_);
    Check("internal node");
    Node node;
    node.child.resize(kNum / 64);
    node.prefix.resize(kNum / 64);
    uint32_t count = 0;
    for (uint32_t w = 0; w < kNum / 64; ++w) {
      node.child[w] = child_mask.template getWord<uint64_t>(w);
      node.prefix[w] = count;
      count += uint32_t(std::popcount(node.child[w]));
    }
    // Tile values: a palette of the distinct ones, packed indices.
    std::vector<uint32_t> index(kNum, 0);
    bool raw = false;
    for (uint32_t n = 0; n < kNum && !raw; ++n) {
      if (child_mask.isOn(n)) continue;
      uint32_t k = 0;
      while (k < node.palette.size() &&
             std::memcmp(&node.palette[k], &values[n], sizeof(ValueT)) != 0)
        ++k;
      if (k == node.palette.size()) {
        if (k == 256) {
          raw = true;
          break;
        }
        node.palette.push_back(values[n]);
      }
      index[n] = k;
    }
    if (raw) {
      node.palette.assign(values.get(), values.get() + kNum);
      node.bits = 0xff;
    } else if (node.palette.size() > 1) {
      const size_t p = node.palette.size();
      node.bits = p <= 2 ? 1 : p <= 4 ? 2 : p <= 16 ? 4 : 8;
      node.packed.assign((size_t(kNum) * node.bits + 7) / 8, 0);
      for (uint32_t n = 0; n < kNum; ++n) {
        const uint32_t bit = n * node.bits;
        node.packed[bit >> 3] |= uint8_t(index[n] << (bit & 7));
      }
    }
    // Active tiles.
    for (auto it = value_mask.beginOn(); it; ++it) {
      const uint32_t n = it.pos();
      if (child_mask.isOn(n)) continue;
      const Coord o = Local<kLog2, kChildTotal>(origin, n);
      t_.tiles_.push_back({CoordBBox::createCube(o, 1 << kChildTotal), values[n]});
      t_.active_voxels_ += uint64_t(1) << (3 * kChildTotal);
    }
    if constexpr (kLog2 == 5) {
      node.first_child = uint32_t(t_.lower_.size());
      t_.upper_.push_back(std::move(node));
      for (auto it = child_mask.beginOn(); it; ++it)
        Internal<4, 3>(Local<kLog2, kChildTotal>(origin, it.pos()));
    } else {
      node.first_child = uint32_t(t_.leaves_.size());
      t_.lower_.push_back(std::move(node));
      for (auto it = child_mask.beginOn(); it; ++it) {
        const Coord o = Local<kLog2, kChildTotal>(origin, it.pos());
        Mask m;
        m.load(is_);
        Check("leaf mask");
        t_.leaves_.push_back({{o.x(), o.y(), o.z()}, m.countOn(), 0});
      }
    }
  }

  void Check(const char* what) {
    if (!is_.good())
      throw openvdb::IoError(std::string("truncated or corrupt ") + what + " near byte " +
                             std::to_string(uint64_t(is_.tellg())));
  }

 private:
  template <int kLog2, int kChildTotal>
  static Coord Local(const Coord& origin, uint32_t n) {
    const int x = int(n >> (2 * kLog2)), y = int((n >> kLog2) & ((1u << kLog2) - 1)),
              z = int(n & ((1u << kLog2) - 1));
    return origin + Coord(x << kChildTotal, y << kChildTotal, z << kChildTotal);
  }

  CompactTopology& t_;
  std::istream& is_;
  uint64_t file_size_;
};

template <class ValueT>
CompactTopology<ValueT>::~CompactTopology() {
  if (fd_ >= 0) ::close(fd_);
}

template <class ValueT>
uint64_t CompactTopology<ValueT>::MemoryBytes() const {
  uint64_t b = leaves_.capacity() * sizeof(Leaf) + tiles_.capacity() * sizeof(Tile) +
               root_.size() * 32 + root_tiles_.capacity() * sizeof(ValueT);
  for (const Node& n : upper_) b += n.Bytes();
  for (const Node& n : lower_) b += n.Bytes();
  return b;
}

// Refuses, before reading any of its bytes, a grid vox cannot read.
static Status CheckReadableGrid(const std::string& path, const VdbLayout& layout,
                                const VdbLayout::Grid& grid, const std::string& where) {
  if (!layout.has_offsets || layout.file_version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
    return UnsupportedError(path + ": VDB file format " + std::to_string(layout.file_version) +
                            " predates OpenVDB 3 (format 222); re-save it with a newer OpenVDB");
  if (grid.instance) return UnsupportedError(where + " is an instance of another grid");
  return OkStatus();
}

template <class ValueT>
StatusOr<std::unique_ptr<CompactTopology<ValueT>>> CompactTopology<ValueT>::Read(
    const std::string& path, const VdbLayout& layout, const VdbLayout::Grid& grid) {
  const std::string where = "grid '" + grid.name + "' in " + path;
  VOX_RETURN_IF_ERROR(CheckReadableGrid(path, layout, grid, where));
  std::unique_ptr<CompactTopology> t(new CompactTopology);
  t->path_ = path;
  t->file_version_ = layout.file_version;
  t->lib_major_ = layout.library_major;
  t->lib_minor_ = layout.library_minor;
  t->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (t->fd_ < 0) return IoError(path + ": " + std::strerror(errno));
  struct stat st;
  if (::fstat(t->fd_, &st) != 0) return IoError(path + ": " + std::strerror(errno));
  const uint64_t size = uint64_t(st.st_size);
  if (grid.end_pos > size || grid.grid_pos >= grid.end_pos)
    return CorruptionError(where + ": grid bytes run past the end of the file");
  // The grid's bytes, mapped and read once front to back; pages behind the
  // read position are dropped as it goes.
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, t->fd_, 0);
  if (map == MAP_FAILED) return IoError(path + ": cannot map: " + std::strerror(errno));
  struct Unmap {
    void* p;
    uint64_t n;
    ~Unmap() { ::munmap(p, n); }
  } unmap{map, size};
  ::madvise(map, size, MADV_SEQUENTIAL);
  MemoryBuf buf(static_cast<const char*>(map), size, 0);
  std::istream is(&buf);
  openvdb::io::setVersion(is, openvdb::VersionId(t->lib_major_, t->lib_minor_),
                          t->file_version_);
  try {
    is.seekg(std::streamoff(grid.grid_pos));
    uint32_t compression = 0;
    is.read(reinterpret_cast<char*>(&compression), 4);
    t->compression_ = compression;
    openvdb::io::setDataCompression(is, compression);
    openvdb::MetaMap meta;
    meta.readMeta(is);
    if (openvdb::Metadata::ConstPtr half = meta["is_saved_as_half_float"])
      t->half_ = half->asBool();
    openvdb::math::Transform xform;
    xform.read(is);
    int32_t buffer_count = 0;
    is.read(reinterpret_cast<char*>(&buffer_count), 4);
    is.read(reinterpret_cast<char*>(&t->background_), sizeof(ValueT));
    openvdb::io::setGridBackgroundValuePtr(is, &t->background_);
    uint32_t tiles = 0, children = 0;
    is.read(reinterpret_cast<char*>(&tiles), 4);
    is.read(reinterpret_cast<char*>(&children), 4);
    Parser p(*t, is, size);
    p.Check("grid header");
    if (buffer_count != 1)
      return UnsupportedError(where + " has " + std::to_string(buffer_count) +
                              " buffers per leaf; vox reads single-buffer trees");
    if (uint64_t(tiles) + children > (grid.end_pos - grid.grid_pos) / 12)
      return CorruptionError(where + ": root node claims " + std::to_string(tiles) +
                             " tiles and " + std::to_string(children) + " children");
    // At most one leaf per 64-byte mask in the topology section.
    t->leaves_.reserve((grid.block_pos - grid.grid_pos) / 64 + 1);
    for (uint32_t n = 0; n < tiles; ++n) {
      int32_t v[3];
      ValueT value;
      bool active = false;
      is.read(reinterpret_cast<char*>(v), 12);
      is.read(reinterpret_cast<char*>(&value), sizeof(ValueT));
      is.read(reinterpret_cast<char*>(&active), 1);
      p.Check("root tile");
      const Coord o(v[0], v[1], v[2]);
      t->root_[RootKey(o)] = ~int64_t(t->root_tiles_.size());
      t->root_tiles_.push_back(value);
      if (active) {
        t->tiles_.push_back({CoordBBox::createCube(o, 1 << kRootLog2), value});
        t->active_voxels_ += uint64_t(1) << (3 * kRootLog2);
      }
    }
    for (uint32_t n = 0; n < children; ++n) {
      int32_t v[3];
      is.read(reinterpret_cast<char*>(v), 12);
      p.Check("root child");
      const Coord o(v[0], v[1], v[2]);
      t->root_[RootKey(o)] = int64_t(t->upper_.size());
      p.template Internal<5, 7>(o);
    }
    ::madvise(map, grid.block_pos & ~uint64_t(4095), MADV_DONTNEED);
    if (uint64_t(is.tellg()) != grid.block_pos)
      return CorruptionError(where + ": its topology ends at byte " +
                             std::to_string(uint64_t(is.tellg())) + ", not at byte " +
                             std::to_string(grid.block_pos) + " where its descriptor says");
    // The leaf buffers, in the same order: note where each starts, skip the values.
    const uint64_t kDrop = uint64_t(64) << 20;
    uint64_t dropped = grid.block_pos & ~uint64_t(4095);
    for (Leaf& leaf : t->leaves_) {
      leaf.pos = uint64_t(is.tellg());
      Mask m;
      m.load(is);
      if (m.countOn() != leaf.active)
        return CorruptionError(where + ": the leaf at (" + std::to_string(leaf.origin[0]) + "," +
                               std::to_string(leaf.origin[1]) + "," +
                               std::to_string(leaf.origin[2]) +
                               ") has a different value mask in its buffer than in the topology");
      openvdb::io::readCompressedValues<ValueT, Mask>(is, nullptr, 512, m, t->half_);
      p.Check("leaf values");
      t->active_voxels_ += leaf.active;
      if (leaf.pos - dropped > kDrop) {
        const uint64_t upto = leaf.pos & ~uint64_t(4095);
        ::madvise(static_cast<char*>(map) + dropped, upto - dropped, MADV_DONTNEED);
        ::posix_fadvise(t->fd_, off_t(dropped), off_t(upto - dropped), POSIX_FADV_DONTNEED);
        dropped = upto;
      }
    }
    t->leaves_end_ = uint64_t(is.tellg());
    if (t->leaves_end_ > grid.end_pos)
      return CorruptionError(where + ": leaf values run past the grid's end");
  } catch (const openvdb::Exception& e) {
    return CorruptionError(where + ": cannot read its topology: " + e.what());
  }
  ::posix_fadvise(t->fd_, 0, 0, POSIX_FADV_DONTNEED);
  return t;
}

template <class ValueT>
typename CompactTopology<ValueT>::Where CompactTopology<ValueT>::Lookup(const Coord& c) const {
  Where w;
  auto it = root_.find(RootKey(c));
  if (it == root_.end()) {
    w.value = background_;
    return w;
  }
  if (it->second < 0) {
    w.value = root_tiles_[size_t(~it->second)];
    return w;
  }
  const Node& upper = upper_[size_t(it->second)];
  const uint32_t n2 = (uint32_t((c.x() & 4095) >> 7) << 10) |
                      (uint32_t((c.y() & 4095) >> 7) << 5) | uint32_t((c.z() & 4095) >> 7);
  if (!upper.IsChild(n2)) {
    w.value = upper.Tile(n2);
    return w;
  }
  const Node& lower = lower_[upper.Rank(n2)];
  const uint32_t n1 = (uint32_t((c.x() & 127) >> 3) << 8) | (uint32_t((c.y() & 127) >> 3) << 4) |
                      uint32_t((c.z() & 127) >> 3);
  if (!lower.IsChild(n1)) {
    w.value = lower.Tile(n1);
    return w;
  }
  w.leaf = int64_t(lower.Rank(n1));
  return w;
}

template <class ValueT>
void CompactTopology<ValueT>::ReadLeaf(size_t i, ValueT values[512], Mask* mask,
                                       std::vector<char>* scratch) const {
  const uint64_t begin = leaves_[i].pos;
  const uint64_t end = i + 1 < leaves_.size() ? leaves_[i + 1].pos : leaves_end_;
  scratch->resize(end - begin);
  uint64_t done = 0;
  while (done < end - begin) {
    const ssize_t r = ::pread(fd_, scratch->data() + done, end - begin - done, off_t(begin + done));
    if (r <= 0) {
      if (r < 0 && errno == EINTR) continue;
      throw openvdb::IoError(path_ + ": cannot read leaf values at byte " +
                             std::to_string(begin + done) + ": " +
                             (r < 0 ? std::strerror(errno) : "end of file"));
    }
    done += uint64_t(r);
  }
  MemoryBuf buf(scratch->data(), end - begin, begin);
  std::istream is(&buf);
  openvdb::io::setVersion(is, openvdb::VersionId(lib_major_, lib_minor_), file_version_);
  openvdb::io::setDataCompression(is, compression_);
  openvdb::io::setGridBackgroundValuePtr(is, &background_);
  mask->load(is);
  CheckValueChunk<ValueT>(is, 512, *mask, half_);
  openvdb::io::readCompressedValues<ValueT, Mask>(is, values, 512, *mask, half_);
  if (is.fail())
    throw openvdb::IoError(path_ + ": corrupt leaf values at byte " + std::to_string(begin));
}

template class CompactTopology<float>;
template class CompactTopology<double>;

}  // namespace vox::ingest_internal

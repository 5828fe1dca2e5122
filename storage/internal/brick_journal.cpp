// The journal of a resumable store write: see brick_journal.h.
#include "storage/internal/brick_journal.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "core/util/crc32c.h"

namespace vox::storage_internal {
namespace {

constexpr char kMagic[8] = {'V', 'O', 'X', 'J', 'R', 'N', 'L', '1'};
constexpr size_t kRecordBodySize = kTableEntrySize + 6 * 4;
constexpr size_t kRecordSize = kRecordBodySize + 4;

void Put32(std::string* s, uint32_t v) {
  char b[4];
  std::memcpy(b, &v, 4);
  s->append(b, 4);
}
void Put64(std::string* s, uint64_t v) {
  char b[8];
  std::memcpy(b, &v, 8);
  s->append(b, 8);
}
uint32_t Get32(const char* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}
uint64_t Get64(const char* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}

std::string Header(const std::string& key, uint64_t store_id) {
  std::string h(kMagic, sizeof kMagic);
  Put64(&h, store_id);
  Put32(&h, uint32_t(key.size()));
  h += key;
  Put32(&h, crc32c::Mask(crc32c::Value(h.data(), h.size())));
  return h;
}

Status WriteAll(int fd, const std::string& bytes, const std::string& path) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      return IoError("cannot write '" + path + "': " + std::strerror(errno));
    }
    done += size_t(w);
  }
  return OkStatus();
}

// Reads n bytes at `offset`; false when the file is shorter.
bool ReadAt(int fd, uint64_t offset, size_t n, char* out) {
  size_t done = 0;
  while (done < n) {
    const ssize_t r = ::pread(fd, out + done, n - done, off_t(offset + done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    done += size_t(r);
  }
  return true;
}

}  // namespace

std::string JournalKey(const std::string& caller_key, const StoreMeta& m, int zstd_level,
                       int normal_bits) {
  std::string k = caller_key + "\n" + m.source_file + "\n" + m.grid_name;
  char buf[512];
  std::snprintf(buf, sizeof buf, "\n%d %d %d %lld %lld %lld %.17g %.17g %.17g %d%d%d%d%d %d %d",
                int(m.grid_class), m.levels, m.brick_level, (long long)m.origin.x,
                (long long)m.origin.y, (long long)m.origin.z, m.isovalue, m.threshold, m.voxel_size,
                m.has_normal, m.has_density, m.has_color, m.has_coverage, m.has_temperature,
                zstd_level, normal_bits);
  k += buf;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      std::snprintf(buf, sizeof buf, " %.17g", m.index_to_world[i][j]);
      k += buf;
    }
  return k;
}

BrickJournal::~BrickJournal() {
  if (fd_ >= 0) ::close(fd_);
}

uint64_t BrickJournal::JournalBytes(const std::string& key, size_t records) {
  return sizeof kMagic + 8 + 4 + key.size() + 4 + uint64_t(records) * kRecordSize;
}

StatusOr<std::unique_ptr<BrickJournal>> BrickJournal::Create(const std::string& path,
                                                             const std::string& key,
                                                             uint64_t store_id) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) return IoError("cannot create '" + path + "': " + std::strerror(errno));
  std::unique_ptr<BrickJournal> j(new BrickJournal(path, fd));
  VOX_RETURN_IF_ERROR(WriteAll(fd, Header(key, store_id), path));
  return j;
}

StatusOr<std::unique_ptr<BrickJournal>> BrickJournal::Reopen(const std::string& path,
                                                             uint64_t keep_bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return IoError("cannot open '" + path + "': " + std::strerror(errno));
  std::unique_ptr<BrickJournal> j(new BrickJournal(path, fd));
  if (::ftruncate(fd, off_t(keep_bytes)) != 0 || ::lseek(fd, off_t(keep_bytes), SEEK_SET) < 0)
    return IoError("cannot truncate '" + path + "': " + std::strerror(errno));
  return j;
}

Status BrickJournal::Append(const JournalRecord& r) {
  std::string rec;
  rec.reserve(kRecordSize);
  EncodeBrickEntry(r.entry, &rec);
  for (int a = 0; a < 3; ++a) Put32(&rec, uint32_t(r.lo[a]));
  for (int a = 0; a < 3; ++a) Put32(&rec, uint32_t(r.hi[a]));
  Put32(&rec, crc32c::Mask(crc32c::Value(rec.data(), rec.size())));
  return WriteAll(fd_, rec, path_);
}

StatusOr<JournalContents> BrickJournal::Read(const std::string& path,
                                             const std::string& bricks_path) {
  JournalContents out;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return IoError("cannot open '" + path + "': " + std::strerror(errno));
  const int bfd = ::open(bricks_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (bfd < 0) {
    ::close(fd);
    return IoError("cannot open '" + bricks_path + "': " + std::strerror(errno));
  }
  struct Closer {
    int a, b;
    ~Closer() { ::close(a), ::close(b); }
  } closer{fd, bfd};
  const auto bad = [&](const std::string& why) {
    return CorruptionError("'" + path + "' is not a journal vox can resume from: " + why);
  };
  char head[20];
  if (!ReadAt(fd, 0, sizeof head, head) || std::memcmp(head, kMagic, sizeof kMagic) != 0)
    return bad("no journal header");
  out.store_id = Get64(head + 8);
  const uint32_t key_size = Get32(head + 16);
  if (key_size > (1u << 20)) return bad("a key of " + std::to_string(key_size) + " bytes");
  std::string key(key_size, '\0');
  char crc[4];
  if (!ReadAt(fd, sizeof head, key_size, key.data()) || !ReadAt(fd, sizeof head + key_size, 4, crc))
    return bad("a truncated header");
  const std::string expect = Header(key, out.store_id);
  if (std::memcmp(expect.data() + expect.size() - 4, crc, 4) != 0) return bad("a bad header CRC");
  out.key = key;
  uint8_t bh[kFileHeaderSize];
  if (!ReadAt(bfd, 0, kFileHeaderSize, reinterpret_cast<char*>(bh)))
    return bad("its brick file has no header");
  auto fh = DecodeFileHeader(bh, kBrickMagic, bricks_path);
  if (!fh.ok() || fh->store_id != out.store_id) return bad("its brick file is another store's");
  out.bricks_end = kFileHeaderSize;
  std::string frame;
  for (uint64_t at = expect.size();; at += kRecordSize) {
    char rec[kRecordSize];
    if (!ReadAt(fd, at, kRecordSize, rec)) break;
    if (crc32c::Mask(crc32c::Value(rec, kRecordBodySize)) != Get32(rec + kRecordBodySize)) break;
    JournalRecord r;
    r.entry = DecodeBrickEntry(reinterpret_cast<const uint8_t*>(rec));
    for (int a = 0; a < 3; ++a) r.lo[a] = Get32(rec + kTableEntrySize + 4 * a);
    for (int a = 0; a < 3; ++a) r.hi[a] = Get32(rec + kTableEntrySize + 12 + 4 * a);
    // Bricks are appended one after another: the record's brick must start
    // where the last one ended, and its bytes must match its CRC.
    if (r.entry.offset != out.bricks_end || r.entry.stored_size > (1u << 30)) break;
    frame.resize(r.entry.stored_size + kTrailerSize);
    if (!ReadAt(bfd, r.entry.offset, frame.size(), frame.data())) break;
    const std::string trailer = BlockTrailer(frame.data(), r.entry.stored_size, r.entry.codec);
    if (frame.compare(r.entry.stored_size, kTrailerSize, trailer) != 0) break;
    uint32_t stored_crc;
    std::memcpy(&stored_crc, trailer.data() + 1, 4);
    if (stored_crc != r.entry.crc) break;
    out.bricks_end = r.entry.offset + frame.size();
    out.records.push_back(r);
  }
  return out;
}

}  // namespace vox::storage_internal

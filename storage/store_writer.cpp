// StoreWriter: streams bricks into a temporary directory beside the target,
// then writes the index, fsyncs and renames into place (FORMAT.md).
#include <fcntl.h>
#include <sys/file.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <glm/vector_relational.hpp>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <random>
#include <unordered_map>
#include <unordered_set>

#include "core/util/file.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/brick_journal.h"
#include "storage/internal/format.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using namespace storage_internal;

std::string CoordString(const glm::u64vec3& c) {
  return "(" + std::to_string(c.x) + "," + std::to_string(c.y) + "," + std::to_string(c.z) + ")";
}

struct CoordHash {
  size_t operator()(const glm::u64vec3& c) const {
    uint64_t h = c.x * 0x9E3779B97F4A7C15ull ^
                 (c.y + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full ^
                 (c.z + 0x165667B19E3779F9ull) * 0x27D4EB2F165667C5ull;
    return size_t(h ^ (h >> 29));
  }
};

// One compression context per thread, shared by all writers.
struct CCtxDeleter {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
ZSTD_CCtx* ThreadCCtx() {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxDeleter> cctx(ZSTD_createCCtx());
  return cctx.get();
}

// The voxels as points in Morton order; each point's ref is its voxel's index.
std::vector<LeafPoint> MortonOrder(const std::vector<BrickVoxel>& voxels) {
  std::vector<LeafPoint> pts(voxels.size());
  for (size_t i = 0; i < voxels.size(); ++i)
    pts[i] = {voxels[i].x, voxels[i].y, voxels[i].z, NodeRef(i)};
  SortMorton(&pts);  // voxels handed over in Morton order (ingest's) cost one pass
  return pts;
}

Status ValidateMeta(const StoreMeta& m) {
  if (m.levels < 1 || m.levels > kMaxLevels)
    return InvalidArgumentError("store levels " + std::to_string(m.levels) + " outside 1..40");
  if (m.brick_level < 1 || m.brick_level > m.levels)
    return InvalidArgumentError("brick level " + std::to_string(m.brick_level) + " outside 1.." +
                                std::to_string(m.levels));
  if (m.grid_class != GridClass::kLevelSet && m.grid_class != GridClass::kFogVolume)
    return InvalidArgumentError("unknown grid class " + std::to_string(int(m.grid_class)));
  return OkStatus();
}

// Reads the first `n` bytes (or the last `n` when `from_end`) of a file.
bool ReadBytes(const fs::path& path, bool from_end, size_t n, uint8_t* out) {
  FILE* f = fopen(path.c_str(), "rb");
  if (!f) return false;
  bool ok = fseeko(f, from_end ? -off_t(n) : 0, from_end ? SEEK_END : SEEK_SET) == 0 &&
            fread(out, 1, n, f) == n;
  fclose(f);
  return ok;
}

// Why `dir` is not a complete vox store that --force may replace, or "" when
// it is one: exactly index.vxi and bricks.vxb, regular files (beside a lod/ pyramid), with valid
// headers (and index footer) carrying one store_id (FORMAT.md).
std::string NotAStoreReason(const fs::path& dir) {
  // A pyramid temporary (.lod.tmp-PID-*) of a process that is gone (an
  // interrupted or killed --add-lod) is stale, not foreign data.
  RemoveStaleTemporaries(dir.string(), kLodDirName);
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name == kLodDirName && e.is_directory(ec) && !e.is_symlink(ec)) continue;  // its pyramid
    if (name != kIndexFileName && name != kBrickFileName)
      return "it holds '" + name + "', which is not a store file";
    if (!e.is_regular_file(ec)) return "'" + name + "' is not a regular file";
  }
  if (ec) return "it cannot be listed: " + ec.message();
  const fs::path index = dir / kIndexFileName, bricks = dir / kBrickFileName;
  if (!fs::exists(index, ec)) return std::string("it has no ") + kIndexFileName;
  if (!fs::exists(bricks, ec)) return std::string("it has no ") + kBrickFileName;
  uint8_t ih[kFileHeaderSize], bh[kFileHeaderSize], foot[kFooterSize];
  if (!ReadBytes(index, false, kFileHeaderSize, ih) || !ReadBytes(index, true, kFooterSize, foot))
    return std::string(kIndexFileName) + " is too short to be a store index";
  if (!ReadBytes(bricks, false, kFileHeaderSize, bh))
    return std::string(kBrickFileName) + " is too short to be a brick file";
  auto i = DecodeFileHeader(ih, kIndexMagic, index.string());
  if (!i.ok()) return i.status().message();
  auto b = DecodeFileHeader(bh, kBrickMagic, bricks.string());
  if (!b.ok()) return b.status().message();
  auto f = DecodeFooter(foot, index.string());
  if (!f.ok()) return f.status().message();
  if (i->store_id != b->store_id || i->store_id != f->store_id)
    return "its index and brick file belong to different stores";
  return "";
}

// A fault point for tests of a race between the check and the publish: with
// VOX_TEST_PUBLISH_GATE naming a FIFO in the directory of `target`, Finish
// reads it to its end (waiting for the test to open and close it) just
// before publishing (not the stores inside it, a pyramid's levels).
void WaitAtTestGate(const std::string& target) {
  const char* gate = std::getenv("VOX_TEST_PUBLISH_GATE");
  if (gate == nullptr || *gate == '\0') return;
  std::string gate_dir, target_dir, name;
  SplitPath(gate, &gate_dir, &name);
  SplitPath(target, &target_dir, &name);
  if (gate_dir != target_dir) return;
  const int fd = open(gate, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  char buf[64];
  for (;;) {
    const ssize_t n = read(fd, buf, sizeof buf);
    if (n == 0 || (n < 0 && errno != EINTR)) break;
  }
  close(fd);
}

class StoreWriterImpl : public StoreWriter {
 public:
  StoreWriterImpl(std::string target, std::string temp, CheckedTarget checked, StoreMeta meta,
                  WriteOptions options, uint64_t store_id, bool resumable = false)
      : target_(std::move(target)),
        temp_(std::move(temp)),
        checked_(checked),
        meta_(std::move(meta)),
        options_(options),
        store_id_(store_id),
        resumable_(resumable),
        depth_(meta_.levels - meta_.brick_level),
        flags_(AttrFlags(meta_)) {}

  ~StoreWriterImpl() override {
    bricks_.reset();
    journal_.reset();
    if (!finished_ && !resumable_) {
      std::error_code ec;
      fs::remove_all(temp_, ec);
    }
    if (lock_fd_ >= 0) close(lock_fd_);
  }

  Status Init() {
    if (resumable_) return InitResumable();
    VOX_ASSIGN_OR_RETURN(bricks_, WritableFile::Create(temp_ + "/" + kBrickFileName));
    return bricks_->Append(EncodeFileHeader(kBrickMagic, store_id_));
  }

  uint64_t resumed_bricks() const override { return resumed_.size(); }
  bool Resumed(const glm::u64vec3& c, uint32_t* voxels) const override {
    auto it = resumed_.find(c);
    if (it == resumed_.end()) return false;
    *voxels = it->second;
    return true;
  }
  std::string resume_note() const override { return resume_note_; }

  Status AddBrick(const glm::u64vec3& c, std::vector<BrickVoxel> voxels) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!status_.ok()) return status_;
      if (finished_) return InvalidArgumentError("AddBrick after Finish");
    }
    const uint64_t top_size = uint64_t(1) << meta_.brick_level;
    if (c.x >= top_size || c.y >= top_size || c.z >= top_size)
      return InvalidArgumentError("brick " + CoordString(c) + " outside the 2^" +
                                  std::to_string(meta_.brick_level) + " brick grid");
    if (voxels.empty()) return InvalidArgumentError("brick " + CoordString(c) + " has no voxels");
    const uint64_t local = uint64_t(1) << depth_;
    glm::u64vec3 lo(UINT64_MAX), hi(0);
    for (const BrickVoxel& v : voxels) {
      if (v.x >= local || v.y >= local || v.z >= local)
        return InvalidArgumentError("voxel (" + std::to_string(v.x) + "," + std::to_string(v.y) +
                                    "," + std::to_string(v.z) + ") of brick " + CoordString(c) +
                                    " outside the brick's 2^" + std::to_string(depth_) + " voxels");
      glm::u64vec3 l(v.x, v.y, v.z);
      lo = glm::min(lo, l);
      hi = glm::max(hi, l);
    }
    if (depth_ == 0 && voxels.size() != 1)
      return InvalidArgumentError("brick " + CoordString(c) + " repeats its voxel");
    if (voxels.size() >= kBrickBit)
      return InvalidArgumentError("brick " + CoordString(c) + " has too many voxels");
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!seen_.insert(c).second)
        return InvalidArgumentError("brick " + CoordString(c) + " added twice");
    }
    if (depth_ == 0) {
      // Top-only store: each "brick" is one voxel, kept in the top's payloads.
      std::lock_guard<std::mutex> lock(mu_);
      top_voxels_.push_back({{c.x, c.y, c.z, kEmptyRef}, voxels[0].attr});
      AddBoundsLocked(c, lo, hi, 1);
      return OkStatus();
    }

    // Morton order; payload k is the k-th voxel in that order.
    std::vector<LeafPoint> pts = MortonOrder(voxels);
    std::vector<VoxelAttributes> attrs(pts.size());
    for (size_t k = 0; k < pts.size(); ++k) {
      if (k > 0 && pts[k].x == pts[k - 1].x && pts[k].y == pts[k - 1].y && pts[k].z == pts[k - 1].z)
        return Unsee(
            c, InvalidArgumentError("brick " + CoordString(c) + " has voxel (" +
                                    std::to_string(pts[k].x) + "," + std::to_string(pts[k].y) +
                                    "," + std::to_string(pts[k].z) + ") twice"));
      attrs[k] = voxels[pts[k].ref].attr;
      pts[k].ref = MakeLeafRef(uint32_t(k));
    }
    std::vector<Cell> cells = BuildCells(pts, depth_);
    // Readers hold pools of CompactCells, whose indices fit 24 bits.
    if (cells.size() > size_t(kMaxCompactIndex) + 1 || pts.size() > size_t(kMaxCompactIndex) + 1)
      return Unsee(c, InvalidArgumentError("brick " + CoordString(c) + " has " +
                                           std::to_string(cells.size()) + " cells and " +
                                           std::to_string(pts.size()) +
                                           " voxels; a pool holds at most 2^24: choose fewer "
                                           "levels per brick"));
    std::string raw = EncodeBrickRaw(cells, attrs, depth_, flags_, options_.normal_bits);
    if (raw.size() > kMaxBrickRawBytes)
      return Unsee(
          c, InvalidArgumentError("brick " + CoordString(c) + " is " + std::to_string(raw.size()) +
                                  " bytes; the limit is " + std::to_string(kMaxBrickRawBytes) +
                                  " (choose a deeper brick level)"));
    ZSTD_CCtx* cctx = ThreadCCtx();
    if (cctx == nullptr) return Fail(ResourceExhaustedError("cannot allocate a zstd context"));
    std::string frame(ZSTD_compressBound(raw.size()), '\0');
    size_t z = ZSTD_compressCCtx(cctx, frame.data(), frame.size(), raw.data(), raw.size(),
                                 options_.zstd_level);
    if (ZSTD_isError(z))
      return Fail(InternalError(std::string("zstd compression failed: ") + ZSTD_getErrorName(z)));
    frame.resize(z);
    std::string trailer = BlockTrailer(frame.data(), frame.size(), kCodecZstd);
    BrickEntry e;
    e.x = c.x;
    e.y = c.y;
    e.z = c.z;
    e.stored_size = uint32_t(z);
    e.raw_size = uint32_t(raw.size());
    e.num_cells = uint32_t(cells.size());
    e.voxel_count = uint32_t(attrs.size());
    e.crc = DecodeFixed32Trailer(trailer);
    e.codec = kCodecZstd;

    std::lock_guard<std::mutex> lock(mu_);
    if (!status_.ok()) return status_;
    e.offset = bricks_->size();
    Status s = bricks_->Append(frame);
    if (s.ok()) s = bricks_->Append(trailer);
    if (!s.ok()) return FailLocked(s);
    entries_.push_back(e);
    AddBoundsLocked(c, lo, hi, attrs.size());
    if (journal_) {
      // The brick's bytes reach the file before its record does.
      s = bricks_->Flush();
      if (s.ok()) s = journal_->Append({e, lo, hi});
      if (!s.ok()) return FailLocked(s);
    }
    return OkStatus();
  }

  std::string temp_dir() const override { return temp_; }

  Status Finish() override {
    std::lock_guard<std::mutex> lock(mu_);
    if (!status_.ok()) return status_;
    if (finished_) return InvalidArgumentError("Finish called twice");
    Status s = DoFinish();
    if (!s.ok()) return FailLocked(s);
    finished_ = true;
    return OkStatus();
  }

 private:
  static uint32_t DecodeFixed32Trailer(const std::string& t) {
    uint32_t v;
    std::memcpy(&v, t.data() + 1, 4);
    return v;
  }

  Status Fail(Status s) {
    std::lock_guard<std::mutex> lock(mu_);
    return FailLocked(std::move(s));
  }
  // A failure is sticky; its message names the store being written (the
  // OS error names the temporary file it hit).
  Status FailLocked(Status s) {
    status_ = s.WithContext("writing store '" + target_ + "'");
    return status_;
  }
  // A brick refused after its coordinate was recorded may be added again.
  Status Unsee(const glm::u64vec3& c, Status s) {
    std::lock_guard<std::mutex> lock(mu_);
    seen_.erase(c);
    return s;
  }
  void AddBoundsLocked(const glm::u64vec3& c, const glm::u64vec3& lo, const glm::u64vec3& hi,
                       uint64_t voxels) {
    glm::u64vec3 glo = (c << uint64_t(depth_)) + lo, ghi = (c << uint64_t(depth_)) + hi;
    if (!have_bounds_) {
      gmin_ = glo;
      gmax_ = ghi;
      have_bounds_ = true;
    }
    gmin_ = glm::min(gmin_, glo);
    gmax_ = glm::max(gmax_, ghi);
    voxel_count_ += voxels;
  }

  Status DoFinish() {
    // Bricks are numbered in Morton order of their coordinates.
    std::vector<LeafPoint> pts;
    std::string top_attr;
    if (depth_ == 0) {
      pts.resize(top_voxels_.size());
      for (size_t i = 0; i < top_voxels_.size(); ++i) {
        pts[i] = top_voxels_[i].first;
        pts[i].ref = NodeRef(i);
      }
      SortMorton(&pts);
      std::vector<VoxelAttributes> attrs(pts.size());
      for (size_t k = 0; k < pts.size(); ++k) {
        attrs[k] = top_voxels_[pts[k].ref].second;
        pts[k].ref = MakeLeafRef(uint32_t(k));
      }
      WriteAttributes(attrs, flags_, &top_attr, options_.normal_bits);
    } else {
      std::vector<LeafPoint> order(entries_.size());
      for (size_t i = 0; i < entries_.size(); ++i)
        order[i] = {entries_[i].x, entries_[i].y, entries_[i].z, NodeRef(i)};
      SortMorton(&order);
      std::vector<BrickEntry> sorted(entries_.size());
      for (size_t id = 0; id < order.size(); ++id) {
        sorted[id] = entries_[order[id].ref];
        order[id].ref = MakeBrickRef(uint32_t(id));
      }
      entries_ = std::move(sorted);
      pts = std::move(order);
    }
    std::vector<Cell> top = BuildCells(pts, meta_.brick_level);
    // Readers hold the top as CompactCells, whose indices (cells, brick ids,
    // top-only payloads) fit 24 bits.
    if (top.size() > size_t(kMaxCompactIndex) + 1 || pts.size() > size_t(kMaxCompactIndex) + 1)
      return InvalidArgumentError("the top has " + std::to_string(top.size()) + " cells and " +
                                  std::to_string(pts.size()) + (depth_ == 0 ? " voxels" : " bricks") +
                                  "; a pool holds at most 2^24: choose " +
                                  (depth_ == 0 ? "a lower brick level" : "more brick levels"));

    meta_.voxel_count = voxel_count_;
    meta_.brick_count = entries_.size();
    meta_.top_cells = top.size();
    if (voxel_count_ > 0) {
      meta_.bbox_min = meta_.origin + glm::i64vec3(gmin_);
      meta_.bbox_max = meta_.origin + glm::i64vec3(gmax_);
    } else {
      meta_.bbox_min = glm::i64vec3(0);
      meta_.bbox_max = glm::i64vec3(-1);
    }

    // The index file: header, blocks with trailers, footer.
    VOX_ASSIGN_OR_RETURN(auto index, WritableFile::Create(temp_ + "/" + kIndexFileName));
    VOX_RETURN_IF_ERROR(index->Append(EncodeFileHeader(kIndexMagic, store_id_)));
    Footer f;
    auto put_block = [&](const std::string& block, BlockHandle* h) -> Status {
      h->offset = index->size();
      h->size = block.size();
      VOX_RETURN_IF_ERROR(index->Append(block));
      return index->Append(BlockTrailer(block.data(), block.size(), kCodecRaw));
    };
    std::string table;
    table.reserve(entries_.size() * kTableEntrySize);
    for (const BrickEntry& e : entries_) EncodeBrickEntry(e, &table);
    VOX_RETURN_IF_ERROR(put_block(EncodeMeta(meta_, SummarizeTable(entries_, table)), &f.meta));
    std::string top_bytes(reinterpret_cast<const char*>(top.data()), top.size() * sizeof(Cell));
    VOX_RETURN_IF_ERROR(put_block(top_bytes, &f.top));
    VOX_RETURN_IF_ERROR(put_block(top_attr, &f.top_attr));
    VOX_RETURN_IF_ERROR(put_block(table, &f.table));
    f.brick_file_size = bricks_->size();
    f.store_id = store_id_;
    VOX_RETURN_IF_ERROR(index->Append(EncodeFooter(f)));

    VOX_RETURN_IF_ERROR(bricks_->Sync());
    VOX_RETURN_IF_ERROR(bricks_->Close());
    VOX_RETURN_IF_ERROR(index->Sync());
    VOX_RETURN_IF_ERROR(index->Close());
    VOX_RETURN_IF_ERROR(SyncDir(temp_));
    if (options_.before_publish) {
      VOX_RETURN_IF_ERROR(options_.before_publish(temp_));
      VOX_RETURN_IF_ERROR(SyncDir(temp_));
    }

    WaitAtTestGate(target_);
    // A resumable store's journal stays to the last: until here an error, an
    // interrupt or a kill (in the index or the pyramid) leaves its bricks for
    // the next run, and a directory with a journal is refused as a store
    // (Store::Open). Without it, the directory is the store alone; from here
    // on an error removes it (the next run starts over).
    if (journal_) {
      journal_.reset();
      resumable_ = false;
      if (unlink((temp_ + "/" + kJournalFileName).c_str()) != 0)
        return IoError("cannot remove '" + temp_ + "/" + kJournalFileName + "': " +
                       std::strerror(errno));
      VOX_RETURN_IF_ERROR(SyncDir(temp_));
    }
    // Into place: replace the store (or empty directory) Create found, and
    // only if it is still one; else only where nothing is.
    Status s = PublishAtomically(temp_, target_, "store", checked_, MayReplace);
    if (s.code() == StatusCode::kInvalidArgument && !checked_.exists && !options_.force)
      return InvalidArgumentError(s.message() + " (use --force to replace a store)");
    return s;
  }

  // "" when the directory moved out of the target is still an empty
  // directory or a store, as Create found it.
  static std::string MayReplace(const std::string& old) {
    std::error_code ec;
    if (fs::is_empty(old, ec) && !ec) return "";
    const std::string why = NotAStoreReason(old);
    return why.empty() ? "" : "it is no longer a vox store: " + why;
  }

  // The resumable directory: locked (one writer at a time), then either an
  // earlier run's bricks kept (those its journal verifies) or a fresh start.
  Status InitResumable() {
    std::error_code ec;
    const fs::file_status st = fs::symlink_status(temp_, ec);
    if (fs::exists(st) && !fs::is_directory(st))
      return InvalidArgumentError("'" + temp_ + "' is not a directory (" +
                                  (fs::is_symlink(st) ? "a symbolic link" : "a file") +
                                  "), so not one vox-ingest --resume made: remove it, or "
                                  "ingest without --resume");
    fs::create_directory(temp_, ec);
    if (ec) return IoError("cannot create '" + temp_ + "': " + ec.message());
    lock_fd_ = open(temp_.c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (lock_fd_ < 0) return IoError("cannot open '" + temp_ + "': " + std::strerror(errno));
    if (flock(lock_fd_, LOCK_EX | LOCK_NB) != 0)
      return UnavailableError("'" + temp_ + "' is in use by another resumable ingest of '" +
                              target_ + "'");
    const std::string key =
        JournalKey(options_.resume_key, meta_, options_.zstd_level, options_.normal_bits);
    const std::string bricks = temp_ + "/" + kBrickFileName,
                      journal = temp_ + "/" + kJournalFileName;
    if (fs::exists(journal, ec)) {
      StatusOr<JournalContents> j = BrickJournal::Read(journal, bricks);
      if (!j.ok()) {
        resume_note_ = "starting over: " + j.status().message();
      } else if (j->key != key) {
        resume_note_ = "starting over: '" + temp_ + "' holds another ingest's bricks (another "
                       "input, options or placement)";
      } else if (j->records.empty()) {
        resume_note_ = "starting over: the earlier run in '" + temp_ + "' kept no brick";
      } else {
        return Adopt(*j, key);
      }
    } else {
      // Without a journal, only what a run killed before writing it leaves
      // (its brick file) is removed; anything else is not vox's to delete.
      for (const auto& e : fs::directory_iterator(temp_, ec)) {
        const std::string name = e.path().filename().string();
        if (name != kBrickFileName || !e.is_regular_file(ec) || e.is_symlink(ec))
          return InvalidArgumentError("'" + temp_ + "' holds '" + name +
                                      "' but no journal of vox-ingest --resume: no run to "
                                      "continue, and not removed (it may not be vox's); remove "
                                      "it, or ingest without --resume");
      }
      if (ec) return IoError("cannot list '" + temp_ + "': " + ec.message());
      if (!fs::is_empty(temp_, ec)) resume_note_ = "starting over: '" + temp_ + "' has no journal";
    }
    for (const auto& e : fs::directory_iterator(temp_, ec)) fs::remove_all(e.path(), ec);
    VOX_ASSIGN_OR_RETURN(bricks_, WritableFile::Create(bricks));
    VOX_RETURN_IF_ERROR(bricks_->Append(EncodeFileHeader(kBrickMagic, store_id_)));
    VOX_RETURN_IF_ERROR(bricks_->Flush());
    VOX_ASSIGN_OR_RETURN(journal_, BrickJournal::Create(journal, key, store_id_));
    return OkStatus();
  }

  // Keeps the verified bricks of an earlier run: the brick file and the
  // journal cut after them, anything else (a half-written index or
  // pyramid) removed.
  Status Adopt(const JournalContents& j, const std::string& key) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(temp_, ec)) {
      const std::string name = e.path().filename().string();
      if (name != kBrickFileName && name != kJournalFileName) fs::remove_all(e.path(), ec);
    }
    store_id_ = j.store_id;
    VOX_ASSIGN_OR_RETURN(bricks_, WritableFile::OpenAppend(temp_ + "/" + kBrickFileName,
                                                           j.bricks_end));
    VOX_ASSIGN_OR_RETURN(journal_,
                         BrickJournal::Reopen(temp_ + "/" + kJournalFileName,
                                              BrickJournal::JournalBytes(key, j.records.size())));
    const uint64_t bricks_side = uint64_t(1) << meta_.brick_level,
                   voxels_side = uint64_t(1) << depth_;
    for (const JournalRecord& r : j.records) {
      const glm::u64vec3 c(r.entry.x, r.entry.y, r.entry.z);
      // Its CRC vouches for the bytes, not for what they say: a record
      // outside the store's grid is refused before it is used.
      const bool inside = glm::all(glm::lessThan(c, glm::u64vec3(bricks_side))) &&
                          glm::all(glm::lessThanEqual(r.lo, r.hi)) &&
                          glm::all(glm::lessThan(r.hi, glm::u64vec3(voxels_side))) &&
                          r.entry.voxel_count > 0 &&
                          uint64_t(r.entry.voxel_count) <= voxels_side * voxels_side * voxels_side;
      if (!inside)
        return CorruptionError("the journal in '" + temp_ + "' lists a brick outside the store's "
                               "grid: remove the directory to start over");
      if (!seen_.insert(c).second) return CorruptionError("a journal lists a brick twice");
      entries_.push_back(r.entry);
      AddBoundsLocked(c, r.lo, r.hi, r.entry.voxel_count);
      resumed_[c] = r.entry.voxel_count;
    }
    resume_note_ = "resuming: " + std::to_string(j.records.size()) + " bricks of an earlier run "
                   "verified in '" + temp_ + "'";
    return OkStatus();
  }

  const std::string target_, temp_;
  const CheckedTarget checked_;
  StoreMeta meta_;
  const WriteOptions options_;
  uint64_t store_id_;
  bool resumable_ = false;  // until the journal is removed, just before publishing
  int lock_fd_ = -1;
  std::unique_ptr<BrickJournal> journal_;
  std::unordered_map<glm::u64vec3, uint32_t, CoordHash> resumed_;
  std::string resume_note_;
  const int depth_;
  const uint8_t flags_;
  std::unique_ptr<WritableFile> bricks_;
  std::vector<BrickEntry> entries_;
  std::unordered_set<glm::u64vec3, CoordHash> seen_;
  std::vector<std::pair<LeafPoint, VoxelAttributes>> top_voxels_;
  std::mutex mu_;  // guards everything below, the brick file and status_
  uint64_t voxel_count_ = 0;
  glm::u64vec3 gmin_{0}, gmax_{0};
  bool have_bounds_ = false;
  Status status_;
  bool finished_ = false;
};

}  // namespace

std::string ResumeDirectory(const std::string& dir) {
  std::string target = dir;
  while (target.size() > 1 && target.back() == '/') target.pop_back();
  std::string parent, name;
  SplitPath(target, &parent, &name);
  return (parent == "/" ? "" : parent) + "/." + name + ".resume";
}

std::string ResumeJournal(const std::string& dir) {
  return ResumeDirectory(dir) + "/" + kJournalFileName;
}

StatusOr<std::unique_ptr<StoreWriter>> StoreWriter::Create(const std::string& dir,
                                                           const StoreMeta& meta,
                                                           const WriteOptions& options) {
  VOX_RETURN_IF_ERROR(ValidateMeta(meta));
  if (options.zstd_level < ZSTD_minCLevel() || options.zstd_level > ZSTD_maxCLevel())
    return InvalidArgumentError("zstd level " + std::to_string(options.zstd_level) + " outside " +
                                std::to_string(ZSTD_minCLevel()) + ".." +
                                std::to_string(ZSTD_maxCLevel()));
  if (options.normal_bits < 8 || options.normal_bits > 16)
    return InvalidArgumentError("normal precision " + std::to_string(options.normal_bits) +
                                " bits outside 8..16");
  std::string target = dir;
  while (target.size() > 1 && target.back() == '/') target.pop_back();
  if (target.empty()) return InvalidArgumentError("empty store path");
  // What Finish may replace: what is there now, if it passes the checks
  // below (Finish checks again that it is still the same and still a store).
  StatusOr<CheckedTarget> checked = CheckTarget(target);
  if (!checked.ok()) return checked.status();
  fs::path tp(target);
  std::error_code ec;
  auto st = fs::symlink_status(tp, ec);
  if (!ec && fs::exists(st)) {
    if (!options.force)
      return InvalidArgumentError("'" + target + "' already exists (use --force to replace it)");
    // Replace only a complete store or an empty directory, never other data.
    if (!fs::is_directory(st))
      return InvalidArgumentError("'" + target +
                                  "' exists and is not a directory; --force replaces only a vox "
                                  "store or an empty directory");
    if (!fs::is_empty(tp, ec)) {
      const std::string why = NotAStoreReason(tp);
      if (!why.empty())
        return InvalidArgumentError("'" + target + "' is not a vox store (" + why +
                                    "); --force replaces only a vox store or an empty directory");
    }
  }
  fs::path parent = tp.parent_path();
  if (parent.empty()) parent = ".";
  if (!fs::is_directory(parent, ec))
    return NotFoundError("cannot create store '" + target + "': directory '" + parent.string() +
                         "' does not exist");
  std::random_device rd;
  uint64_t id = (uint64_t(rd()) << 32) ^ rd() ^
                uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
  const bool resumable = !options.resume_key.empty() && meta.levels > meta.brick_level;
  StatusOr<std::string> temp = resumable ? StatusOr<std::string>(ResumeDirectory(target))
                                         : CreateTemporary(target, /*directory=*/true);
  if (!temp.ok()) return temp.status().WithContext("store '" + target + "'");
  auto w = std::make_unique<StoreWriterImpl>(target, *temp, *checked, meta, options,
                                             options.store_id != 0 ? options.store_id : id,
                                             resumable);
  Status init = w->Init();
  if (!init.ok()) return init.WithContext("writing store '" + target + "'");
  return std::unique_ptr<StoreWriter>(std::move(w));
}

}  // namespace vox

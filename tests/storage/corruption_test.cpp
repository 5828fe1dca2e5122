// Bad stores: every byte of the index flipped, brick records flipped,
// truncated and missing files, wrong magic and versions, a file shrinking
// under an open store. Always a clear Status naming the file, never a crash.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include "core/tracer.h"
#include "core/util/crc32c.h"
#include "core/util/file.h"
#include "storage/internal/coding.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/internal/store_impl.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using namespace storage_internal;
using storage_test::ReadFile;
using storage_test::WriteFile;

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

class Corruption : public ::testing::Test {
 protected:
  void SetUp() override {
    auto vol = GenerateShape("sphere:32");
    ASSERT_TRUE(vol.ok());
    voxels_ = vol->voxels;
    meta_ = storage_test::MetaFor(vol->levels, 2, GridClass::kLevelSet, true);
    dir_ = tmp_ / "s";
    ASSERT_TRUE(storage_test::WriteVoxels(dir_, voxels_, meta_).ok());
    index_ = ReadFile(dir_ + "/index.vxi");
    bricks_ = ReadFile(dir_ + "/bricks.vxb");
    ASSERT_GT(index_.size(), kFileHeaderSize + kFooterSize);
  }

  StatusOr<std::unique_ptr<Store>> OpenMem(const std::string& index, const std::string& bricks,
                                           bool verify = true) {
    OpenOptions oo;
    oo.verify_checksums = verify;
    return OpenStoreFromFiles("mem", NewMemoryFile("mem/index.vxi", index),
                              NewMemoryFile("mem/bricks.vxb", bricks), oo);
  }

  // Fetches every brick and traces a few rays; returns the first error.
  Status Exercise(Store& s) {
    for (uint32_t id = 0; id < s.meta().brick_count; ++id) {
      auto b = s.FetchBrick(id);
      if (!b.ok()) return b.status();
      // Whatever was decoded must be structurally sound.
      VOX_RETURN_IF_ERROR(ValidateLevelOrderPool(
          b->cells, b->num_cells, s.meta().levels - s.meta().brick_level, ~0u));
    }
    auto t = Tracer<>::Create(s.view(), s.meta().brick_level);
    if (!t.ok()) return t.status();
    for (int i = 0; i < 16; ++i) {
      Ray r{{-3.0 + i, 10.5, -5}, {0.3, 0.1 * i, 1}};
      VOX_RETURN_IF_ERROR(t->Traverse(r, [&](const Hit& h) {
        return s.Attributes(h.brick, h.payload).ok();
      }));
    }
    return OkStatus();
  }

  storage_test::TempDir tmp_;
  std::string dir_, index_, bricks_;
  std::vector<LeafPoint> voxels_;
  StoreMeta meta_;
};

TEST_F(Corruption, PristineOpens) {
  auto s = OpenMem(index_, bricks_);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_TRUE(Exercise(**s).ok());
}

TEST_F(Corruption, EveryIndexByteFlipped) {
  for (size_t off = 0; off < index_.size(); ++off) {
    for (uint8_t mask : {uint8_t(0x01), uint8_t(0x80)}) {
      std::string bad = index_;
      bad[off] ^= char(mask);
      auto s = OpenMem(bad, bricks_);
      ASSERT_FALSE(s.ok()) << "flip at " << off << " went unnoticed";
      EXPECT_EQ(s.status().code(), StatusCode::kCorruption) << s.status().ToString();
      EXPECT_TRUE(Contains(s.status().message(), "index.vxi")) << s.status().ToString();
    }
  }
}

TEST_F(Corruption, EveryBrickByteFlipped) {
  auto pristine = OpenMem(index_, bricks_);
  ASSERT_TRUE(pristine.ok());
  const std::vector<BrickEntry> table = *BrickTable(**pristine);
  int unverified_ok = 0;
  for (size_t off = 0; off < bricks_.size(); ++off) {
    std::string bad = bricks_;
    bad[off] ^= char(1 << (off % 8));
    auto s = OpenMem(index_, bad);
    if (off < kFileHeaderSize) {
      ASSERT_FALSE(s.ok()) << "header flip at " << off;
      EXPECT_TRUE(Contains(s.status().message(), "bricks.vxb")) << s.status().ToString();
      continue;
    }
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    uint32_t id = 0;
    while (id < table.size() && !(off >= table[id].offset &&
                                  off < table[id].offset + table[id].stored_size + kTrailerSize))
      ++id;
    ASSERT_LT(id, table.size()) << "byte " << off << " belongs to no record";
    auto b = (*s)->FetchBrick(id);
    ASSERT_FALSE(b.ok()) << "flip at " << off << " in brick " << id << " went unnoticed";
    EXPECT_EQ(b.status().code(), StatusCode::kCorruption);
    EXPECT_TRUE(Contains(b.status().message(), "brick " + std::to_string(id) + " ") &&
                Contains(b.status().message(), "bricks.vxb"))
        << b.status().ToString();
    // Other bricks are unaffected.
    EXPECT_TRUE((*s)->FetchBrick(id == 0 ? 1 : 0).ok());
    // Without checksums, decoding still never hands out a bad pool.
    if (off % 7 == 0) {
      auto u = OpenMem(index_, bad, /*verify=*/false);
      ASSERT_TRUE(u.ok());
      Status e = Exercise(**u);
      if (e.ok()) ++unverified_ok;  // a flip in attribute bytes decodes fine
      else EXPECT_EQ(e.code(), StatusCode::kCorruption) << e.ToString();
    }
  }
  SUCCEED() << unverified_ok << " unverified flips decoded to valid bricks";
}

TEST_F(Corruption, TruncatedFiles) {
  for (const char* name : {"index.vxi", "bricks.vxb"}) {
    const std::string& orig = std::string(name) == "index.vxi" ? index_ : bricks_;
    for (size_t len : {size_t(0), size_t(1), size_t(31), size_t(32), orig.size() / 2,
                       orig.size() - 1}) {
      WriteFile(dir_ + "/" + name, orig.substr(0, len));
      auto s = Store::Open(dir_, {});
      ASSERT_FALSE(s.ok()) << name << " truncated to " << len;
      EXPECT_EQ(s.status().code(), StatusCode::kCorruption) << s.status().ToString();
      EXPECT_TRUE(Contains(s.status().message(), name)) << s.status().ToString();
    }
    WriteFile(dir_ + "/" + name, orig);
  }
  // A longer bricks file is also refused.
  WriteFile(dir_ + "/bricks.vxb", bricks_ + "x");
  auto s = Store::Open(dir_, {});
  EXPECT_EQ(s.status().code(), StatusCode::kCorruption);
  WriteFile(dir_ + "/bricks.vxb", bricks_);
  EXPECT_TRUE(Store::Open(dir_, {}).ok());
}

TEST_F(Corruption, TruncatedMessageSaysSo) {
  WriteFile(dir_ + "/bricks.vxb", bricks_.substr(0, bricks_.size() - 100));
  auto s = Store::Open(dir_, {});
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Contains(s.status().message(), "truncated")) << s.status().ToString();
}

TEST_F(Corruption, MissingFilesAndDirectories) {
  auto s = Store::Open(tmp_ / "nope", {});
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s.status().message(), "nope"));
  WriteFile(tmp_ / "file", "hello");
  EXPECT_EQ(Store::Open(tmp_ / "file", {}).status().code(), StatusCode::kInvalidArgument);
  for (const char* name : {"index.vxi", "bricks.vxb"}) {
    std::string p = dir_ + "/" + name;
    ASSERT_EQ(rename(p.c_str(), (p + ".away").c_str()), 0);
    auto m = Store::Open(dir_, {});
    EXPECT_EQ(m.status().code(), StatusCode::kNotFound) << m.status().ToString();
    EXPECT_TRUE(Contains(m.status().message(), name));
    ASSERT_EQ(rename((p + ".away").c_str(), p.c_str()), 0);
  }
}

TEST_F(Corruption, WrongMagicAndGarbage) {
  std::string bad = index_;
  std::memcpy(bad.data(), "NOTAVOX!", 8);
  auto s = OpenMem(bad, bricks_);
  EXPECT_EQ(s.status().code(), StatusCode::kCorruption);
  EXPECT_TRUE(Contains(s.status().message(), "magic")) << s.status().ToString();
  std::mt19937_64 rng(3);
  for (size_t n : {size_t(10), size_t(200), size_t(5000)}) {
    std::string g(n, 0);
    for (char& c : g) c = char(rng());
    EXPECT_FALSE(OpenMem(g, bricks_).ok());
    EXPECT_FALSE(OpenMem(index_, g).ok());
  }
  // Files of another store are not mixed in.
  storage_test::TempDir other;
  ASSERT_TRUE(storage_test::WriteVoxels(other / "s", voxels_, meta_).ok());
  auto mixed = OpenMem(index_, ReadFile(other / "s/bricks.vxb"));
  EXPECT_EQ(mixed.status().code(), StatusCode::kCorruption);
  EXPECT_TRUE(Contains(mixed.status().message(), "different store")) << mixed.status().ToString();
}

// Rewrites the version fields of both headers and the footer, with valid CRCs.
void SetVersion(std::string* file, uint16_t major, uint16_t minor, bool is_index) {
  uint8_t* p = reinterpret_cast<uint8_t*>(file->data());
  EncodeFixed16(p + 8, major);
  EncodeFixed16(p + 10, minor);
  EncodeFixed32(p + 28, crc32c::Mask(crc32c::Value(p, 28)));
  if (is_index) {
    uint8_t* f = p + file->size() - kFooterSize;
    EncodeFixed16(f + 80, major);
    EncodeFixed16(f + 82, minor);
    EncodeFixed32(f + 92, crc32c::Mask(crc32c::Value(f, 92)));
  }
}

TEST_F(Corruption, VersionChecks) {
  std::string idx = index_, bri = bricks_;
  SetVersion(&idx, 2, 0, true);
  auto s = OpenMem(idx, bricks_);
  EXPECT_EQ(s.status().code(), StatusCode::kUnsupported) << s.status().ToString();
  EXPECT_TRUE(Contains(s.status().message(), "format 2.0")) << s.status().ToString();
  SetVersion(&bri, 2, 0, false);
  EXPECT_EQ(OpenMem(index_, bri).status().code(), StatusCode::kUnsupported);
  // A newer minor version of both files is accepted.
  idx = index_;
  bri = bricks_;
  SetVersion(&idx, 1, 9, true);
  SetVersion(&bri, 1, 9, false);
  auto ok = OpenMem(idx, bri);
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_TRUE(Exercise(**ok).ok());
}

TEST_F(Corruption, NewerMinorMayAppendMetadataFields) {
  // Rebuild the index with 12 unknown bytes after the 1.0 metadata fields.
  auto footer = DecodeFooter(reinterpret_cast<const uint8_t*>(index_.data()) + index_.size() -
                                 kFooterSize, "x");
  ASSERT_TRUE(footer.ok());
  Footer f = *footer;
  auto block = [&](const BlockHandle& h) { return index_.substr(h.offset, h.size); };
  std::string meta = block(f.meta) + "future field", top = block(f.top),
              attr = block(f.top_attr), table = block(f.table);
  std::string out = index_.substr(0, kFileHeaderSize);
  auto put = [&](const std::string& b, BlockHandle* h) {
    h->offset = out.size();
    h->size = b.size();
    out += b + BlockTrailer(b.data(), b.size(), kCodecRaw);
  };
  put(meta, &f.meta);
  put(top, &f.top);
  put(attr, &f.top_attr);
  put(table, &f.table);
  f.minor = 1;
  out += EncodeFooter(f);
  SetVersion(&out, 1, 1, true);
  auto s = OpenMem(out, bricks_);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*s)->meta().build_options, meta_.build_options);
  EXPECT_TRUE(Exercise(**s).ok());
}

TEST_F(Corruption, InjectedReadErrorsAreReportedAndNotCached) {
  auto fi = std::make_unique<FaultInjectionFile>(NewMemoryFile("mem/bricks.vxb", bricks_));
  FaultInjectionFile* faults = fi.get();
  auto s = OpenStoreFromFiles("mem", NewMemoryFile("mem/index.vxi", index_), std::move(fi), {});
  ASSERT_TRUE(s.ok());
  faults->FailReadsAfter(0);
  auto b = (*s)->FetchBrick(1);
  EXPECT_EQ(b.status().code(), StatusCode::kIoError);
  EXPECT_TRUE(Contains(b.status().message(), "brick 1 ")) << b.status().ToString();
  faults->FailReadsAfter(-1);
  EXPECT_TRUE((*s)->FetchBrick(1).ok());
  // A flipped byte seen only by the reader (bad RAM, bad disk): checksum.
  // Brick 2's record came with brick 1's window: read it alone.
  for (bool windows : {false, true}) {
    SCOPED_TRACE(windows ? "read windows" : "records alone");
    auto f2 = std::make_unique<FaultInjectionFile>(NewMemoryFile("mem/bricks.vxb", bricks_));
    FaultInjectionFile* flips = f2.get();
    OpenOptions o;
    o.read_windows = windows;
    auto s2 = OpenStoreFromFiles("mem", NewMemoryFile("mem/index.vxi", index_), std::move(f2), o);
    ASSERT_TRUE(s2.ok());
    flips->FlipByte((*BrickTable(**s2))[2].offset + 3, 0x10);
    auto c = (*s2)->FetchBrick(2);
    EXPECT_EQ(c.status().code(), StatusCode::kCorruption);
    EXPECT_TRUE(Contains(c.status().message(), "checksum")) << c.status().ToString();
    // The bad bytes were not kept: once reads are sound again, so is the brick.
    flips->FlipByte(0, 0);
    EXPECT_TRUE((*s2)->FetchBrick(2).ok());
  }
}

TEST_F(Corruption, BrickFileShrinksWhileOpen) {
  OpenOptions alone;
  alone.read_windows = false;
  auto s = Store::Open(dir_, alone);
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->FetchBrick(0).ok());
  ASSERT_EQ(truncate((dir_ + "/bricks.vxb").c_str(), kFileHeaderSize), 0);
  for (uint32_t id = 1; id < (*s)->meta().brick_count; ++id) {
    auto b = (*s)->FetchBrick(id);
    ASSERT_FALSE(b.ok());
    EXPECT_EQ(b.status().code(), StatusCode::kIoError);
    EXPECT_TRUE(Contains(b.status().message(), "bricks.vxb")) << b.status().ToString();
  }
  // A brick cached before the shrink stays usable.
  EXPECT_TRUE((*s)->FetchBrick(0).ok());

  // Reading windows: PrefetchIo.WindowsKeepOnlyWhatTheyReadBeforeAShrink.
}

TEST_F(Corruption, SigbusGuardTurnsFaultIntoIoError) {
  // Without the fstat check, the copy itself faults: the guard must catch it.
  std::string path = dir_ + "/bricks.vxb";
  auto f = OpenMmapFile(path, /*check_size_each_read=*/false);
  ASSERT_TRUE(f.ok());
  const uint64_t size = (*f)->size();
  ASSERT_GT(size, 3 * 4096u);
  std::vector<uint8_t> buf(size);
  ASSERT_TRUE((*f)->Read(0, size, buf.data()).ok());
  ASSERT_EQ(truncate(path.c_str(), 100), 0);
  for (int i = 0; i < 3; ++i) {  // repeatedly: the handler must stay armed
    Status st = (*f)->Read(size - 4096, 4096, buf.data());
    EXPECT_EQ(st.code(), StatusCode::kIoError);
    EXPECT_TRUE(Contains(st.message(), "SIGBUS") && Contains(st.message(), "bricks.vxb"))
        << st.ToString();
  }
  EXPECT_TRUE((*f)->Read(0, 50, buf.data()).ok());
}

TEST_F(Corruption, SigbusOutsideTheGuardStillKills) {
  // The handler only claims faults inside storage's copies; others go to the
  // previous disposition (the default kills by SIGBUS; under ASan, ASan's
  // handler reports and exits 1).
  auto f = OpenMmapFile(dir_ + "/bricks.vxb");
  ASSERT_TRUE(f.ok());
  EXPECT_DEATH(raise(SIGBUS), "");
}

}  // namespace
}  // namespace vox

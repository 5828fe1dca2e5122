// A crafted store whose checksums are all correct but whose one brick
// claims to decode to gigabytes: opening it works, fetching the brick is
// refused (ResourceExhausted naming the brick and the store) before any
// allocation, and vox-info --verify stays small.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zstd.h>

#include <cstdio>
#include <string>

#include "core/util/crc32c.h"
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

// A zstd frame of `n` zero bytes with its content size in the header.
std::string ZeroFrame(uint64_t n) {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, 19);
  ZSTD_CCtx_setPledgedSrcSize(c, n);
  std::string zeros(size_t(1) << 20, '\0'), out;
  std::string buf(ZSTD_CStreamOutSize(), '\0');
  uint64_t left = n;
  for (;;) {
    size_t chunk = size_t(std::min<uint64_t>(left, zeros.size()));
    left -= chunk;
    ZSTD_inBuffer in{zeros.data(), chunk, 0};
    const ZSTD_EndDirective mode = left == 0 ? ZSTD_e_end : ZSTD_e_continue;
    size_t r;
    do {
      ZSTD_outBuffer o{buf.data(), buf.size(), 0};
      r = ZSTD_compressStream2(c, &o, &in, mode);
      out.append(buf.data(), o.pos);
    } while (mode == ZSTD_e_end ? r != 0 : in.pos < in.size);
    if (mode == ZSTD_e_end) break;
  }
  ZSTD_freeCCtx(c);
  return out;
}

class BrickLimit : public ::testing::Test {
 protected:
  // A one-voxel store, then its single brick row rewritten to claim
  // `voxels` voxels and the most cells a 10-level brick may have, its record
  // replaced by a real zstd frame of that many zero bytes, every checksum
  // recomputed.
  void SetUp() override {
    StoreMeta meta = storage_test::MetaFor(12, 2, GridClass::kLevelSet, false);
    dir_ = tmp_ / "crafted";
    ASSERT_TRUE(storage_test::WriteVoxels(dir_, {LeafPoint{5, 6, 7}}, meta).ok());
    const std::string index = ReadFile(dir_ + "/index.vxi");
    const std::string bricks = ReadFile(dir_ + "/bricks.vxb");
    auto footer = DecodeFooter(
        reinterpret_cast<const uint8_t*>(index.data()) + index.size() - kFooterSize, "x");
    ASSERT_TRUE(footer.ok());
    Footer f = *footer;
    auto block = [&](const BlockHandle& h) { return index.substr(h.offset, h.size); };
    auto m = DecodeMeta(reinterpret_cast<const uint8_t*>(index.data()) + f.meta.offset,
                        f.meta.size, "x");
    ASSERT_TRUE(m.ok());
    std::string table = block(f.table);
    ASSERT_EQ(table.size(), kTableEntrySize);
    BrickEntry e = DecodeBrickEntry(reinterpret_cast<const uint8_t*>(table.data()));

    const uint64_t voxels = uint64_t(1) << 27;
    const int depth = 10;
    e.voxel_count = uint32_t(voxels);
    e.num_cells = uint32_t(MaxCells(depth, voxels));
    e.raw_size = uint32_t(kBrickHeaderSize + e.num_cells +
                          voxels * AttrBytesPerVoxel(AttrFlags(*m)));
    ASSERT_LE(e.raw_size, kMaxBrickRawBytes);
    claimed_raw_ = e.raw_size;
    const std::string frame = ZeroFrame(e.raw_size);
    const std::string trailer = BlockTrailer(frame.data(), frame.size(), kCodecZstd);
    e.offset = kFileHeaderSize;
    e.stored_size = uint32_t(frame.size());
    e.codec = kCodecZstd;
    e.crc = DecodeFixed32(reinterpret_cast<const uint8_t*>(trailer.data()) + 1);
    const std::string new_bricks = bricks.substr(0, kFileHeaderSize) + frame + trailer;
    table.clear();
    EncodeBrickEntry(e, &table);
    m->voxel_count = voxels;

    std::string out = index.substr(0, kFileHeaderSize);
    auto put = [&](const std::string& b, BlockHandle* h) {
      h->offset = out.size();
      h->size = b.size();
      out += b + BlockTrailer(b.data(), b.size(), kCodecRaw);
    };
    const std::string top = block(f.top), attr = block(f.top_attr);
    put(EncodeMeta(*m), &f.meta);
    put(top, &f.top);
    put(attr, &f.top_attr);
    put(table, &f.table);
    f.brick_file_size = new_bricks.size();
    out += EncodeFooter(f);
    WriteFile(dir_ + "/index.vxi", out);
    WriteFile(dir_ + "/bricks.vxb", new_bricks);
    store_bytes_ = out.size() + new_bricks.size();
  }

  storage_test::TempDir tmp_;
  std::string dir_;
  uint64_t claimed_raw_ = 0, store_bytes_ = 0;
};

long MaxRssKiB() {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss;
}

TEST_F(BrickLimit, FetchIsRefusedBeforeAllocating) {
  EXPECT_LT(store_bytes_, 64u << 10) << "the crafted store is small";
  EXPECT_GT(claimed_raw_, 500u << 20) << "and claims a brick of over 500 MB";
  OpenOptions oo;
  oo.cache_bytes = size_t(64) << 20;
  auto store = Store::Open(dir_, oo);
  ASSERT_TRUE(store.ok()) << store.status().ToString();  // everything checks out at open
  const long before = MaxRssKiB();
  auto b = (*store)->FetchBrick(0);
  const long grown_mib = (MaxRssKiB() - before) / 1024;
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.status().code(), StatusCode::kResourceExhausted) << b.status().ToString();
  const std::string msg = b.status().message();
  EXPECT_NE(msg.find("brick 0 of store '" + dir_ + "'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("memory budget allows one brick"), std::string::npos) << msg;
  EXPECT_LT(grown_mib, 64) << "the fetch allocated before refusing";
  // The same through prefetch: nothing is decoded or cached.
  uint32_t id = 0;
  (*store)->Prefetch({&id, 1});
  (*store)->CancelPrefetch();
  EXPECT_FALSE((*store)->FetchBrick(0).ok());
  EXPECT_LT((MaxRssKiB() - before) / 1024, 64);
}

TEST_F(BrickLimit, VoxInfoVerifyStaysSmall) {
  const std::string cmd = std::string(VOX_INFO_BIN) + " " + dir_ + " --verify";
  pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    freopen("/dev/null", "w", stdout);
    freopen((dir_ + "/../err.txt").c_str(), "w", stderr);
    execl(VOX_INFO_BIN, VOX_INFO_BIN, dir_.c_str(), "--verify", (char*)nullptr);
    _exit(127);
  }
  int status = 0;
  struct rusage ru;
  ASSERT_EQ(wait4(pid, &status, 0, &ru), pid);
  ASSERT_TRUE(WIFEXITED(status)) << cmd;
  EXPECT_EQ(WEXITSTATUS(status), 1) << cmd;
  const std::string err = ReadFile(tmp_ / "err.txt");
  EXPECT_NE(err.find("brick 0 of store"), std::string::npos) << err;
  EXPECT_NE(err.find("memory budget allows one brick"), std::string::npos) << err;
#ifndef VOX_SANITIZED
  EXPECT_LT(ru.ru_maxrss / 1024, 200) << "vox-info --verify peak RSS in MiB";
#endif
}

}  // namespace
}  // namespace vox

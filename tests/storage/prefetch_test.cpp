// Store::Prefetch and the brick reads under it: prefetched bricks equal
// fetched ones bit for bit, a corrupt brick's error reaches its fetch,
// prefetch racing fetches through a tiny cache gives the same answers, a
// truncated file gives a clear error, and a brick read costs about its own
// bytes of disk I/O.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <numeric>
#include <random>
#include <thread>

#include "core/util/file.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/internal/store_impl.h"
#include "tests/storage/test_util.h"

namespace vox {
namespace {

using namespace storage_internal;

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

using storage_test::BrickBytes;

// Waits until the prefetcher has settled `n` requests (cached, failed or dropped).
void WaitForPrefetch(const Store& s, uint64_t n) {
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < deadline) {
    CacheStats c = s.cache_stats();
    if (c.prefetched + c.prefetch_failed + c.prefetch_dropped >= n) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ADD_FAILURE() << "prefetch did not settle " << n << " requests in 30 s";
}

class Prefetch : public ::testing::Test {
 protected:
  void SetUp() override {
    auto vol = GenerateShape("sphere:64");
    ASSERT_TRUE(vol.ok());
    meta_ = storage_test::MetaFor(vol->levels, 3, GridClass::kLevelSet, true);
    dir_ = tmp_ / "s";
    ASSERT_TRUE(storage_test::WriteVoxels(dir_, vol->voxels, meta_).ok());
    auto plain = Store::Open(dir_, {});
    ASSERT_TRUE(plain.ok()) << plain.status().ToString();
    n_ = uint32_t((*plain)->meta().brick_count);
    ASSERT_GT(n_, 50u);
    for (uint32_t id = 0; id < n_; ++id) {
      auto b = (*plain)->FetchBrick(id);
      ASSERT_TRUE(b.ok());
      truth_.push_back(BrickBytes(*b));
    }
    table_ = *BrickTable(**plain);
  }

  std::vector<uint32_t> AllIds() const {
    std::vector<uint32_t> ids(n_);
    std::iota(ids.begin(), ids.end(), 0u);
    return ids;
  }

  storage_test::TempDir tmp_;
  std::string dir_;
  StoreMeta meta_;
  uint32_t n_ = 0;
  std::vector<std::string> truth_;
  std::vector<BrickEntry> table_;
};

TEST_F(Prefetch, PrefetchedBricksEqualFetchedOnes) {
  auto s = Store::Open(dir_, {});
  ASSERT_TRUE(s.ok());
  std::vector<uint32_t> ids = AllIds();
  std::shuffle(ids.begin(), ids.end(), std::mt19937(7));
  ids.push_back(n_ + 5);  // unknown ids are ignored
  (*s)->Prefetch(ids);
  WaitForPrefetch(**s, n_);
  CacheStats before = (*s)->cache_stats();
  EXPECT_EQ(before.prefetched, n_);
  EXPECT_EQ(before.prefetch_failed, 0u);
  EXPECT_EQ(before.misses, 0u);
  // Coalesced runs: the whole file is read about once.
  EXPECT_LE(before.bytes_read, uint64_t(std::filesystem::file_size(dir_ + "/bricks.vxb")));
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrick(id);
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    EXPECT_EQ(BrickBytes(*b), truth_[id]) << "brick " << id;
  }
  CacheStats after = (*s)->cache_stats();
  EXPECT_EQ(after.prefetch_hits, n_);
  EXPECT_EQ(after.misses, 0u);
  EXPECT_EQ(after.bytes_read, before.bytes_read);
}

// The no-wait fetch the renderer's deferred misses use: a brick not in
// memory is Unavailable at once and read nothing; once prefetched it is
// served, equal to a plain fetch. Bad ids keep their clear error.
TEST_F(Prefetch, FetchIfReadyNeverReads) {
  auto s = Store::Open(dir_, {});
  ASSERT_TRUE(s.ok());
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrickIfReady(id);
    ASSERT_FALSE(b.ok());
    EXPECT_EQ(b.status().code(), StatusCode::kUnavailable) << b.status().ToString();
  }
  EXPECT_EQ((*s)->cache_stats().bytes_read, 0u);
  EXPECT_EQ((*s)->cache_stats().misses, 0u);
  auto bad = (*s)->FetchBrickIfReady(n_ + 3);
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  std::vector<uint32_t> ids = AllIds();
  (*s)->Prefetch(ids);
  WaitForPrefetch(**s, n_);
  EXPECT_GT((*s)->PrefetchBacklog(), 0u);  // read ahead, not yet used
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrickIfReady(id);
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    EXPECT_EQ(BrickBytes(*b), truth_[id]) << "brick " << id;
  }
  EXPECT_EQ((*s)->PrefetchBacklog(), 0u);
  EXPECT_EQ((*s)->cache_stats().misses, 0u);
}

TEST_F(Prefetch, BudgetBoundsPrefetchedBytes) {
  OpenOptions oo;
  oo.cache_bytes = 64 << 10;
  auto s = Store::Open(dir_, oo);
  ASSERT_TRUE(s.ok());
  std::vector<uint32_t> ids = AllIds();
  (*s)->Prefetch(ids);
  WaitForPrefetch(**s, n_);
  CacheStats c = (*s)->cache_stats();
  EXPECT_GT(c.prefetch_dropped, 0u);
  EXPECT_LE(c.bytes_resident, oo.cache_bytes / 2);
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrick(id);
    ASSERT_TRUE(b.ok());
    EXPECT_EQ(BrickBytes(*b), truth_[id]);
  }
}

TEST_F(Prefetch, CorruptBrickIsReportedByItsFetch) {
  const uint32_t bad = n_ / 2;
  std::string bricks = storage_test::ReadFile(dir_ + "/bricks.vxb");
  bricks[table_[bad].offset + table_[bad].stored_size / 2] ^= 0x40;
  storage_test::WriteFile(dir_ + "/bricks.vxb", bricks);
  auto s = Store::Open(dir_, {});
  ASSERT_TRUE(s.ok());
  std::vector<uint32_t> ids = AllIds();
  (*s)->Prefetch(ids);
  WaitForPrefetch(**s, n_);
  EXPECT_EQ((*s)->cache_stats().prefetch_failed, 1u);
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrick(id);
    if (id == bad) {
      ASSERT_FALSE(b.ok());
      EXPECT_EQ(b.status().code(), StatusCode::kCorruption);
      EXPECT_TRUE(Contains(b.status().message(), "brick " + std::to_string(bad) + " "))
          << b.status().ToString();
      EXPECT_TRUE(Contains(b.status().message(), "bricks.vxb")) << b.status().ToString();
    } else {
      ASSERT_TRUE(b.ok()) << b.status().ToString();
      EXPECT_EQ(BrickBytes(*b), truth_[id]);
    }
  }
}

TEST_F(Prefetch, ConcurrentPrefetchAndFetchThroughTinyCache) {
  OpenOptions oo;
  oo.cache_bytes = 48 << 10;  // a few bricks: constant eviction
  auto s = Store::Open(dir_, oo);
  ASSERT_TRUE(s.ok());
  std::atomic<bool> stop{false};
  std::atomic<int> wrong{0}, errors{0};
  std::thread prefetcher([&] {
    std::mt19937 rng(3);
    while (!stop) {
      std::vector<uint32_t> ids(1 + rng() % 64);
      uint32_t start = rng() % n_;
      for (size_t i = 0; i < ids.size(); ++i) ids[i] = (start + uint32_t(i)) % n_;
      (*s)->Prefetch(ids);
      if (rng() % 8 == 0) (*s)->CancelPrefetch();
      std::this_thread::yield();
    }
  });
  std::vector<std::thread> fetchers;
  for (int t = 0; t < 4; ++t) {
    fetchers.emplace_back([&, t] {
      std::mt19937 rng(100 + t);
      for (int i = 0; i < 3000; ++i) {
        uint32_t id = rng() % n_;
        auto b = (*s)->FetchBrick(id);
        if (!b.ok()) {
          ++errors;
        } else if (BrickBytes(*b) != truth_[id]) {
          ++wrong;
        }
      }
    });
  }
  for (auto& f : fetchers) f.join();
  stop = true;
  prefetcher.join();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_EQ(errors.load(), 0);
  CacheStats c = (*s)->cache_stats();
  EXPECT_GT(c.prefetched, 0u);
  EXPECT_LE(c.bytes_resident, oo.cache_bytes);
  s->reset();  // closing with requests queued must not hang
}

TEST_F(Prefetch, TruncatedWhileOpenGivesClearError) {
  auto s = Store::Open(dir_, {});
  ASSERT_TRUE(s.ok());
  const uint64_t size = std::filesystem::file_size(dir_ + "/bricks.vxb");
  const uint64_t cut = size / 3;
  ASSERT_EQ(truncate((dir_ + "/bricks.vxb").c_str(), off_t(cut)), 0);
  std::vector<uint32_t> ids = AllIds();
  (*s)->Prefetch(ids);
  WaitForPrefetch(**s, n_);
  int failed = 0;
  for (uint32_t id = 0; id < n_; ++id) {
    auto b = (*s)->FetchBrick(id);
    if (table_[id].offset + table_[id].stored_size + kTrailerSize > cut) {
      ASSERT_FALSE(b.ok()) << id;
      ++failed;
      EXPECT_EQ(b.status().code(), StatusCode::kIoError);
      EXPECT_TRUE(Contains(b.status().message(), "bricks.vxb") &&
                  Contains(b.status().message(), "shrank") &&
                  Contains(b.status().message(), "brick " + std::to_string(id) + " "))
          << b.status().ToString();
    } else {
      ASSERT_TRUE(b.ok()) << b.status().ToString();
      EXPECT_EQ(BrickBytes(*b), truth_[id]);
    }
  }
  EXPECT_GT(failed, int(n_ / 2));
  EXPECT_GE((*s)->cache_stats().prefetch_failed, uint64_t(failed));
}

TEST(PreadFile, ReadsAndRefusesRangesPastTheEnd) {
  storage_test::TempDir tmp;
  std::string data(10000, '\0');
  for (size_t i = 0; i < data.size(); ++i) data[i] = char(i * 7);
  storage_test::WriteFile(tmp / "f", data);
  auto f = OpenPreadFile(tmp / "f");
  ASSERT_TRUE(f.ok());
  std::vector<uint8_t> buf(5000);
  ASSERT_TRUE((*f)->Read(4000, 5000, buf.data()).ok());
  EXPECT_EQ(std::memcmp(buf.data(), data.data() + 4000, 5000), 0);
  Status past = (*f)->Read(6000, 5000, buf.data());
  EXPECT_EQ(past.code(), StatusCode::kCorruption);
  EXPECT_TRUE(Contains(past.message(), tmp / "f")) << past.ToString();
  auto missing = OpenPreadFile(tmp / "nope");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

// A sphere:256 store with bricks of 32^3 voxels (records of a few KB, as
// vox-ingest makes them), in `dir`.
// Bricks shuffled in the file, or in Morton order as vox-ingest and vox-gen
// write them (`morton`): windows gather the records of neighbouring ids.
Status WriteSphereStore(const std::string& dir, bool morton = false) {
  auto vol = GenerateShape("sphere:256");
  if (!vol.ok()) return vol.status();
  StoreMeta meta = storage_test::MetaFor(vol->levels, vol->levels - 5, GridClass::kLevelSet, true);
  return storage_test::WriteVoxels(dir, vol->voxels, meta, {}, 1, true, /*shuffle_bricks=*/!morton);
}

// Bytes read from disk for a brick: its record's pages, not a read-around.
TEST(PrefetchIo, DiskBytesPerBrickAreTheBricksOwn) {
  storage_test::TempDir tmp;
  const std::string dir = tmp / "s";
  ASSERT_TRUE(WriteSphereStore(dir).ok());
  const std::string path = dir + "/bricks.vxb";
  int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  ASSERT_GE(fd, 0);
  auto drop = [&] {
    fdatasync(fd);
    ASSERT_EQ(posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED), 0);
  };
  // Does this file system count reads for this process at all?
  drop();
  auto io0 = ProcessIoBytes();
  if (!io0.ok()) GTEST_SKIP() << io0.status().ToString();
  std::vector<uint8_t> probe(64 << 10);
  ASSERT_EQ(pread(fd, probe.data(), probe.size(), 0), ssize_t(probe.size()));
  if (*ProcessIoBytes() - *io0 < probe.size())
    GTEST_SKIP() << "no per-process read accounting for " << path;

  OpenOptions alone;
  alone.read_windows = false;
  auto s = Store::Open(dir, alone);
  ASSERT_TRUE(s.ok());
  const std::vector<BrickEntry> table = *BrickTable(**s);
  const uint32_t n = uint32_t(table.size());
  drop();
  // Every 5th brick: records far enough apart not to share pages.
  uint64_t pages = 0, stored = 0, count = 0;
  const uint64_t before = *ProcessIoBytes();
  for (uint32_t id = 1; id < n; id += 5) {
    ASSERT_TRUE((*s)->FetchBrick(id).ok());
    const BrickEntry& e = table[id];
    const uint64_t end = e.offset + e.stored_size + kTrailerSize;
    pages += (end + 4095) / 4096 - e.offset / 4096;
    stored += e.stored_size + kTrailerSize;
    ++count;
  }
  const uint64_t read = *ProcessIoBytes() - before;
  EXPECT_GE(read, stored / 2) << "fetches should miss the dropped page cache";
  EXPECT_LE(read, pages * 4096) << count << " bricks of " << stored << " bytes, file of "
                                << std::filesystem::file_size(path);

  // Prefetched in coalesced runs: at most 1.5x the records' bytes (plus page rounding).
  auto s2 = Store::Open(dir, {});
  ASSERT_TRUE(s2.ok());
  drop();
  std::vector<uint32_t> ids;
  stored = 0;
  for (uint32_t id = 0; id < n; ++id) {
    if (id % 4 == 3) continue;
    ids.push_back(id);
    stored += table[id].stored_size + kTrailerSize;
  }
  const uint64_t before2 = *ProcessIoBytes();
  (*s2)->Prefetch(ids);
  WaitForPrefetch(**s2, ids.size());
  const uint64_t read2 = *ProcessIoBytes() - before2;
  EXPECT_LE((*s2)->cache_stats().bytes_read, stored * 3 / 2 + 8192);
  EXPECT_LE(read2, stored * 3 / 2 + 16 * 4096) << stored;

  // Read in windows (the default): fetching every brick reads each byte of
  // the file once, in one read per window.
  OpenOptions windows;
  windows.cache_bytes = size_t(64) << 20;  // windows of 64 KiB
  auto s3 = Store::Open(dir, windows);
  ASSERT_TRUE(s3.ok());
  drop();
  const uint64_t before3 = *ProcessIoBytes();
  for (uint32_t id = 0; id < n; ++id) ASSERT_TRUE((*s3)->FetchBrick(id).ok());
  const uint64_t read3 = *ProcessIoBytes() - before3;
  const uint64_t file = std::filesystem::file_size(path);
  const CacheStats c3 = (*s3)->cache_stats();
  ASSERT_EQ(c3.window_bytes, uint64_t(64) << 10);
  uint64_t records = 0;
  for (const BrickEntry& e : table) records += e.stored_size + kTrailerSize;
  EXPECT_EQ(c3.bytes_read, records);  // every record once, nothing else
  EXPECT_LE(read3, file + 16 * 4096);
  EXPECT_LE(c3.windows_read, file / c3.window_bytes + 1);
  EXPECT_LT(c3.windows_read, uint64_t(n) / 4) << "a window serves many bricks";
  close(fd);
}

// A brick file that shrinks under an open store read in windows: the records
// of windows read before (checksums verified then) still serve, every other
// brick fails with an I/O error naming the file. (A Morton-ordered store, so
// that brick 0's window holds every record starting in its span.)
TEST(PrefetchIo, WindowsKeepOnlyWhatTheyReadBeforeAShrink) {
  storage_test::TempDir tmp;
  const std::string dir = tmp / "s";
  ASSERT_TRUE(WriteSphereStore(dir, /*morton=*/true).ok());
  OpenOptions windows;
  windows.cache_bytes = size_t(64) << 20;  // windows of 64 KiB
  auto w = Store::Open(dir, windows);
  ASSERT_TRUE(w.ok());
  ASSERT_TRUE((*w)->FetchBrick(0).ok());
  const uint64_t window = (*w)->cache_stats().window_bytes;
  ASSERT_EQ(window, uint64_t(64) << 10);
  const std::vector<BrickEntry> table = *BrickTable(**w);
  ASSERT_GT(std::filesystem::file_size(dir + "/bricks.vxb"), 4 * window);
  ASSERT_EQ(truncate((dir + "/bricks.vxb").c_str(), kFileHeaderSize), 0);
  int served = 0;
  for (uint32_t id = 1; id < (*w)->meta().brick_count; ++id) {
    auto b = (*w)->FetchBrick(id);
    const bool read_before = table[id].offset / window == table[0].offset / window;
    EXPECT_EQ(b.ok(), read_before) << "brick " << id << ": " << b.status().ToString();
    if (b.ok()) {
      ++served;
      continue;
    }
    EXPECT_EQ(b.status().code(), StatusCode::kIoError);
    EXPECT_NE(b.status().message().find("bricks.vxb"), std::string::npos) << b.status().ToString();
  }
  EXPECT_GT(served, 0);
}

}  // namespace
}  // namespace vox

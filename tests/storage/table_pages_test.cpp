// The brick table read a page at a time (storage/internal/table_pages.h): a
// paged store serves every brick bit for bit as one whose table was read
// whole; opening it reads none of the table, a fetch reads the page of its
// row; a corrupt row is reported, naming the index file and the page, by the
// fetches of its page only, and by the whole read vox-info --verify makes; a
// store of format 1.1 (no page CRCs) is checked whole at open, then pages;
// record windows still serve neighbours without a table-wide order; an
// index larger than the memory budget is refused before it is read.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "storage/internal/brick_codec.h"
#include "storage/internal/coding.h"
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

OpenOptions Paged() {
  OpenOptions o;
  o.whole_table_bytes = 0;
  return o;
}

class TablePagesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Bricks of 4^3 over a sphere shell: several thousand bricks, several pages.
    auto vol = GenerateShape("sphere:256");
    ASSERT_TRUE(vol.ok());
    meta_ = storage_test::MetaFor(vol->levels, vol->levels - 2, GridClass::kLevelSet, true);
    dir_ = tmp_ / "s";
    ASSERT_TRUE(storage_test::WriteVoxels(dir_, vol->voxels, meta_).ok());
    index_ = storage_test::ReadFile(dir_ + "/index.vxi");
    auto footer = DecodeFooter(
        reinterpret_cast<const uint8_t*>(index_.data()) + index_.size() - kFooterSize, "x");
    ASSERT_TRUE(footer.ok());
    footer_ = *footer;
  }

  // The index with its metadata re-encoded with `summary` (1.1 when empty)
  // and the table block replaced by `table`.
  std::string Reindex(const TableSummary& summary, const std::string& table) {
    Footer f = footer_;
    auto block = [&](const BlockHandle& h) { return index_.substr(h.offset, h.size); };
    auto m = DecodeMeta(reinterpret_cast<const uint8_t*>(index_.data()) + f.meta.offset,
                        f.meta.size, "x");
    EXPECT_TRUE(m.ok());
    std::string out = index_.substr(0, kFileHeaderSize);
    auto put = [&](const std::string& b, BlockHandle* h) {
      h->offset = out.size();
      h->size = b.size();
      out += b + BlockTrailer(b.data(), b.size(), kCodecRaw);
    };
    const std::string top = block(f.top), attr = block(f.top_attr);
    put(EncodeMeta(*m, summary), &f.meta);
    put(top, &f.top);
    put(attr, &f.top_attr);
    put(table, &f.table);
    out += EncodeFooter(f);
    return out;
  }
  std::string Table() const { return index_.substr(footer_.table.offset, footer_.table.size); }
  TableSummary Summary() const {
    TableSummary t;
    auto m = DecodeMeta(reinterpret_cast<const uint8_t*>(index_.data()) + footer_.meta.offset,
                        footer_.meta.size, "x", &t);
    EXPECT_TRUE(m.ok());
    return t;
  }

  storage_test::TempDir tmp_;
  std::string dir_, index_;
  Footer footer_;
  StoreMeta meta_;
};

TEST_F(TablePagesTest, WriterRecordsPagesAndBounds) {
  const TableSummary t = Summary();
  ASSERT_EQ(t.page_rows, kTablePageRows);
  auto s = Store::Open(dir_, {});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  const uint64_t n = (*s)->meta().brick_count;
  ASSERT_GT(n, 3 * uint64_t(kTablePageRows)) << "the test wants several pages";
  EXPECT_EQ(t.page_crcs.size(), (n + kTablePageRows - 1) / kTablePageRows);
  auto rows = BrickTable(**s);
  ASSERT_TRUE(rows.ok()) << rows.status().ToString();
  uint32_t max_cells = 0, max_vox = 0, max_stored = 0;
  uint64_t cells = 0;
  for (const BrickEntry& e : *rows) {
    max_cells = std::max(max_cells, e.num_cells);
    max_vox = std::max(max_vox, e.voxel_count);
    max_stored = std::max(max_stored, e.stored_size);
    cells += e.num_cells;
  }
  EXPECT_EQ(t.max_num_cells, max_cells);
  EXPECT_EQ(t.max_voxel_count, max_vox);
  EXPECT_EQ(t.max_stored_size, max_stored);
  EXPECT_EQ(t.sum_num_cells, cells);
}

TEST_F(TablePagesTest, PagedServesTheSameBricksAndReadsOnlyWhatItUses) {
  auto whole = Store::Open(dir_, {});
  auto paged = Store::Open(dir_, Paged());
  ASSERT_TRUE(whole.ok() && paged.ok());
  EXPECT_EQ((*paged)->cache_stats().bytes_read, 0u) << "a paged open reads no row";
  EXPECT_EQ((*whole)->brick_sizes().max_decoded, (*paged)->brick_sizes().max_decoded);
  EXPECT_EQ((*whole)->brick_sizes().mean_decoded, (*paged)->brick_sizes().mean_decoded);
  // One brick: one page of rows (and the brick's window).
  ASSERT_TRUE((*paged)->FetchBrick(5).ok());
  const uint64_t n = (*paged)->meta().brick_count;
  EXPECT_LT((*paged)->cache_stats().bytes_read, n * kTableEntrySize / 2);
  for (uint32_t id = 0; id < n; ++id) {
    auto a = (*whole)->FetchBrick(id);
    auto b = (*paged)->FetchBrick(id);
    ASSERT_TRUE(a.ok() && b.ok()) << id;
    ASSERT_EQ(BrickBytes(*a), BrickBytes(*b)) << "brick " << id;
  }
  // Windows still gather neighbours: far fewer reads than bricks.
  EXPECT_LT((*paged)->cache_stats().windows_read, n / 4);
  EXPECT_FALSE((*paged)->FetchBrick(uint32_t(n)).ok());
}

TEST_F(TablePagesTest, ACorruptRowFailsItsPageOnly) {
  std::string table = Table();
  const size_t row = 3 * kTablePageRows + 17;
  table[row * kTableEntrySize + 44] ^= 0x01;  // its voxel count
  storage_test::WriteFile(dir_ + "/index.vxi", Reindex(Summary(), table));
  // Read whole at open (the default for a small table): refused at open.
  auto whole = Store::Open(dir_, {});
  ASSERT_FALSE(whole.ok());
  EXPECT_EQ(whole.status().code(), StatusCode::kCorruption);
  // Paged: opens; bricks of other pages read; those of page 3 fail, naming it.
  auto s = Store::Open(dir_, Paged());
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_TRUE((*s)->FetchBrick(0).ok());
  EXPECT_TRUE((*s)->FetchBrick(4 * kTablePageRows + 1).ok());
  for (uint32_t id : {uint32_t(3 * kTablePageRows), uint32_t(row)}) {
    auto b = (*s)->FetchBrick(id);
    ASSERT_FALSE(b.ok()) << id;
    EXPECT_EQ(b.status().code(), StatusCode::kCorruption);
    EXPECT_TRUE(Contains(b.status().message(), "index.vxi") &&
                Contains(b.status().message(), "page 3"))
        << b.status().ToString();
  }
  // The whole read (vox-info --verify) finds it too.
  auto all = BrickTable(**s);
  ASSERT_FALSE(all.ok());
  EXPECT_TRUE(Contains(all.status().message(), "page 3")) << all.status().ToString();
}

TEST_F(TablePagesTest, ARowBeyondTheSummaryIsRefused) {
  // A row whose CRC is right but that claims more voxels than the metadata's largest brick.
  TableSummary t = Summary();
  std::string table = Table();
  const size_t row = kTablePageRows + 2;
  auto* p = reinterpret_cast<uint8_t*>(table.data()) + row * kTableEntrySize;
  t.max_voxel_count = DecodeFixed32(p + 44) - 1;
  t.page_crcs[1] = TablePageCrc(reinterpret_cast<const uint8_t*>(table.data()) +
                                    kTablePageRows * kTableEntrySize,
                                kTablePageRows * kTableEntrySize);
  storage_test::WriteFile(dir_ + "/index.vxi", Reindex(t, table));
  auto s = Store::Open(dir_, Paged());
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  auto b = (*s)->FetchBrick(uint32_t(row));
  ASSERT_FALSE(b.ok());
  EXPECT_TRUE(Contains(b.status().message(), "largest brick")) << b.status().ToString();
}

TEST_F(TablePagesTest, Format11StoresAreCheckedWholeThenPaged) {
  auto truth = Store::Open(dir_, {});
  ASSERT_TRUE(truth.ok());
  storage_test::WriteFile(dir_ + "/index.vxi", Reindex(TableSummary{}, Table()));
  auto s = Store::Open(dir_, Paged());
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ((*truth)->brick_sizes().max_decoded, (*s)->brick_sizes().max_decoded);
  const uint64_t n = (*s)->meta().brick_count;
  for (uint32_t id = 0; id < n; id += 97) {
    auto a = (*truth)->FetchBrick(id);
    auto b = (*s)->FetchBrick(id);
    ASSERT_TRUE(a.ok() && b.ok()) << id;
    ASSERT_EQ(BrickBytes(*a), BrickBytes(*b)) << "brick " << id;
  }
  // Without page CRCs, a bad row is found at open, whatever the table's size.
  std::string table = Table();
  table[(2 * kTablePageRows + 5) * kTableEntrySize + 3] ^= 0x40;  // an offset
  storage_test::WriteFile(dir_ + "/index.vxi", Reindex(TableSummary{}, table));
  auto bad = Store::Open(dir_, Paged());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kCorruption);
  EXPECT_TRUE(Contains(bad.status().message(), "index.vxi")) << bad.status().ToString();
}

TEST_F(TablePagesTest, AnIndexLargerThanTheBudgetIsRefusedBeforeItIsRead) {
  OpenOptions o;
  o.budget_bytes = 4096;
  auto s = Store::Open(dir_, o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kResourceExhausted);
  EXPECT_TRUE(Contains(s.status().message(), "needs about") &&
              Contains(s.status().message(), dir_))
      << s.status().ToString();
  o.budget_bytes = uint64_t(64) << 20;
  EXPECT_TRUE(Store::Open(dir_, o).ok());
}

}  // namespace
}  // namespace vox

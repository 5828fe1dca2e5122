// vox-render inside a memory cgroup a quarter of the store's size, as a
// Slurm job with a small --mem would run it: with default flags it must not
// be killed, and its image must be the one an unlimited run makes, bit for
// bit. The store (a thick sphere shell with normals and noisy colours, so
// that its bricks compress poorly and decode to several times their size on
// disk) is written here with StoreWriter. Needs a writable memory cgroup
// (root); skipped otherwise.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "render/exr.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/common/cgroup_util.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;

// A shell of radius [r_in, r_out] voxels about the grid's centre, written
// brick by brick (never all voxels at once).
Status WriteShellStore(const std::string& dir, int levels, int brick_level, double r_in, double r_out) {
  StoreMeta meta;
  meta.source_file = "cgroup_render_test";
  meta.grid_name = "shell";
  meta.grid_class = GridClass::kLevelSet;
  meta.levels = levels;
  meta.brick_level = brick_level;
  const int64_t n = int64_t(1) << levels;
  meta.origin = glm::i64vec3(-n / 2);
  meta.bbox_min = glm::i64vec3(-int64_t(std::ceil(r_out)) - 1);
  meta.bbox_max = glm::i64vec3(int64_t(std::ceil(r_out)) + 1);
  meta.index_to_world = glm::dmat4(1.0);
  meta.voxel_size = 1.0;
  meta.has_normal = true;
  meta.has_color = true;
  WriteOptions wo;
  wo.force = true;
  VOX_ASSIGN_OR_RETURN(auto writer, StoreWriter::Create(dir, meta, wo));
  const int sub = levels - brick_level;
  const int64_t side = int64_t(1) << sub, bricks = int64_t(1) << brick_level;
  const double c = double(n) / 2;
  for (int64_t bz = 0; bz < bricks; ++bz)
    for (int64_t by = 0; by < bricks; ++by)
      for (int64_t bx = 0; bx < bricks; ++bx) {
        // Skip bricks whose box misses the shell.
        double near = 0, far = 0;
        for (double lo : {double(bx * side), double(by * side), double(bz * side)}) {
          const double hi = lo + side, d0 = lo - c, d1 = hi - c;
          const double dn = d0 > 0 ? d0 : (d1 < 0 ? -d1 : 0.0);
          const double df = std::max(std::abs(d0), std::abs(d1));
          near += dn * dn;
          far += df * df;
        }
        if (std::sqrt(near) > r_out || std::sqrt(far) < r_in) continue;
        std::vector<BrickVoxel> voxels;
        for (uint32_t z = 0; z < side; ++z)
          for (uint32_t y = 0; y < side; ++y)
            for (uint32_t x = 0; x < side; ++x) {
              const glm::dvec3 d = glm::dvec3(bx * side + x, by * side + y, bz * side + z) - c;
              const double r = std::sqrt(glm::dot(d, d));
              if (r < r_in || r > r_out) continue;
              BrickVoxel v;
              v.x = x;
              v.y = y;
              v.z = z;
              v.attr.normal = glm::vec3(d / r);
              // Noise in the colours' low bits: poor compression, as measured data has.
              uint32_t h = uint32_t(((bx * side + x) * 73856093) ^ ((by * side + y) * 19349663) ^
                                    ((bz * side + z) * 83492791));
              h ^= h >> 13;
              h *= 0x5bd1e995u;
              h ^= h >> 15;
              v.attr.color = glm::vec3(0.5f + float(h & 0xff) / 1024.0f, 0.5f + float((h >> 8) & 0xff) / 1024.0f,
                                       0.5f + float((h >> 16) & 0xff) / 1024.0f);
              voxels.push_back(v);
            }
        if (voxels.empty()) continue;
        VOX_RETURN_IF_ERROR(writer->AddBrick(glm::u64vec3(bx, by, bz), std::move(voxels)));
      }
  return writer->Finish();
}

uint64_t DirBytes(const std::string& dir) {
  uint64_t total = 0;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) total += e.file_size();
  return total;
}

class CgroupRenderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "vox_cgroup_render_" + std::to_string(::getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string dir_;
};

TEST_F(CgroupRenderTest, QuarterOfTheStoreAtDefaultFlags) {
  VOX_REQUIRE_MEMORY_CGROUP();
  const std::string store = dir_ + "/shell.store";
  // 1024^3 grid, bricks of 32^3: a shell 20 voxels thick, about 58M voxels,
  // some 240 MiB on disk. A quarter of it (60 MiB) leaves a budgeted render
  // room beyond its fixed costs (about 20 MiB: code, libraries, buffers).
  ASSERT_TRUE(WriteShellStore(store, 10, 5, 460.0, 480.0).ok());
  const uint64_t store_bytes = DirBytes(store);
  const uint64_t limit = store_bytes / 4;
  RecordProperty("store_mib", std::to_string(store_bytes / kMiB));
  RecordProperty("limit_mib", std::to_string(limit / kMiB));

  auto render = [&](const std::string& name, uint64_t limit_bytes, std::vector<std::string> flags) {
    CgroupRunOptions o;
    o.limit_bytes = limit_bytes;
    o.drop_page_cache = true;  // cold: the store's pages are read (and charged) by the render
    o.stderr_path = dir_ + "/" + name + ".log";
    std::vector<std::string> argv = {VOX_RENDER_BIN, store, "-o", dir_ + "/" + name + ".exr",
                                     "--size", "256x256", "--quiet"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    return RunInMemoryCgroup(argv, o);
  };
  auto free_run = render("unlimited", 0, {});
  ASSERT_TRUE(free_run.ok()) << free_run.status().ToString();
  ASSERT_EQ(free_run->exit_code, 0) << free_run->Describe() << "\n" << ReadAll(dir_ + "/unlimited.log");
  RecordProperty("unlimited_peak_mib", std::to_string(free_run->peak_bytes / kMiB));
  printf("store %llu MiB, limit %llu MiB; unlimited: %s\n", (unsigned long long)(store_bytes / kMiB),
         (unsigned long long)(limit / kMiB), free_run->Describe().c_str());
  // The store must be big enough that an unbounded render would not fit:
  // otherwise the limited run below proves nothing.
  ASSERT_GT(free_run->peak_bytes, limit)
      << "store " << store_bytes / kMiB << " MiB too small for the test: " << free_run->Describe();
  auto a = ReadExr(dir_ + "/unlimited.exr");
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(a->info.complete);
  // The image is not empty: the shell covers about a fifth of the default
  // camera's frame (measured 15124 of 65536 pixels).
  size_t hits = 0;
  for (float alpha : a->pixels.at("A")) hits += alpha > 0.0f;
  EXPECT_GT(hits, a->pixels.at("A").size() / 8);

  // A limited run: not killed, within the limit, the unlimited run's pixels bit for bit.
  auto check_limited = [&](const std::string& name, std::vector<std::string> flags) {
    SCOPED_TRACE(name);
    auto run = render(name, limit, flags);
    ASSERT_TRUE(run.ok()) << run.status().ToString();
    RecordProperty(name + "_peak_mib", std::to_string(run->peak_bytes / kMiB));
    printf("%s, limited to %llu MiB: %s\n", name.c_str(), (unsigned long long)(limit / kMiB),
           run->Describe().c_str());
    EXPECT_FALSE(run->oom_killed) << "vox-render was OOM-killed in a " << limit / kMiB << " MiB cgroup (store "
                                  << store_bytes / kMiB << " MiB): " << run->Describe();
    ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(dir_ + "/" + name + ".log");
    EXPECT_LE(run->peak_bytes, limit);
    auto b = ReadExr(dir_ + "/" + name + ".exr");
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    ASSERT_TRUE(b->info.complete);
    ASSERT_EQ(a->pixels.size(), b->pixels.size());
    for (const auto& [channel, pa] : a->pixels) {
      ASSERT_EQ(b->pixels.count(channel), 1u) << channel;
      const std::vector<float>& pb = b->pixels.at(channel);
      ASSERT_EQ(pa.size(), pb.size()) << channel;
      size_t differ = 0;
      for (size_t i = 0; i < pa.size(); ++i) differ += std::memcmp(&pa[i], &pb[i], sizeof(float)) != 0;
      EXPECT_EQ(differ, 0u) << "channel " << channel << ": " << differ << " pixels differ";
    }
  };
  // Default flags: what a user runs. A small explicit cache must fit too
  // (and shows the comparison itself passes where the render survives).
  check_limited("default_flags", {});
  check_limited("cache_8mb", {"--cache-mb", "8"});
}

}  // namespace
}  // namespace vox::testing

// Long out-of-core checks (label long; need root and a writable memory cgroup,
// skipped otherwise), as a batch job with a memory limit runs vox:
//  - the full view of an 8192^3 sphere store in a 256 MiB cgroup, cold: not
//    killed, peak within the limit, every EXR channel bit-identical to the
//    unlimited cold run (wall times of both are printed, not judged: the
//    ratio is a benchmark, docs/benchmarks.md);
//  - a store larger than this machine's RAM, written by vox-gen in a 1 GiB
//    cgroup, rendered in a 1 GiB cgroup: neither is killed, both peaks stay
//    within the limit, and the image's silhouette is the sphere's, pixel for
//    pixel, wherever the exact sphere passes more than two voxels from the
//    pixel's centre ray.
// Environment: VOX_LONG_STORE_8192 names an existing 8192^3 sphere store to
// use (else vox-gen writes one, about 550 MiB); VOX_LONG_BIG_SIZE and
// VOX_LONG_BIG_BAND choose the big store's grid and band (default: 32768 and
// the smallest band whose estimated store exceeds MemTotal); VOX_LONG_DIR
// holds the stores (default: the test's temp dir; several tens of GB).
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "render/exr.h"
#include "storage/store.h"
#include "tests/common/cgroup_util.h"

namespace vox::testing {
namespace {

namespace fs = std::filesystem;
constexpr uint64_t kMiB = uint64_t(1) << 20;

std::string Env(const char* name, const std::string& fallback = "") {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? std::string(v) : fallback;
}

uint64_t DirBytes(const std::string& dir) {
  uint64_t total = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) total += e.file_size();
  return total;
}

uint64_t MemTotalBytes() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  uint64_t kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit)
    if (key == "MemTotal:") return kb * 1024;
  return 0;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

class OutOfCoreLong : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = Env("VOX_LONG_DIR", ::testing::TempDir() + "vox_ooc_long_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    std::ofstream(dir_ + "/cam.json")
        << R"({"position":[0,0,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":40,)"
           R"("width":1024,"height":1024,"projection":"perspective"})";
    std::ofstream(dir_ + "/scene.json")
        << R"({"lights":[{"type":"directional","direction":[-1,-1,-1],"intensity":1.0,"shadows":false}]})";
  }
  void TearDown() override {
    for (const std::string& p : made_) fs::remove_all(p);
  }

  // vox-gen sphere of `size` and `band` into `store`, in a cgroup of `limit` bytes.
  void Generate(const std::string& store, uint64_t size, double band, uint64_t limit) {
    made_.push_back(store);
    CgroupRunOptions o;
    o.limit_bytes = limit;
    o.stderr_path = store + ".gen.log";
    made_.push_back(o.stderr_path);
    const auto t0 = std::chrono::steady_clock::now();
    auto run = RunInMemoryCgroup({VOX_GEN_BIN, "sphere", store, "--size", std::to_string(size),
                                  "--band", std::to_string(band), "--no-lod", "--force", "--quiet"},
                                 o);
    ASSERT_TRUE(run.ok()) << run.status().ToString();
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    printf("vox-gen sphere --size %llu --band %g: %.0f s, %s, store %llu MiB\n",
           (unsigned long long)size, band, secs, run->Describe().c_str(),
           (unsigned long long)(fs::exists(store) ? DirBytes(store) / kMiB : 0));
    EXPECT_FALSE(run->oom_killed) << run->Describe();
    ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(o.stderr_path);
    if (limit > 0) {
      EXPECT_LE(run->peak_bytes, limit);
    }
  }

  // One cold frame of `store` in a cgroup of `limit` bytes (0: unlimited).
  StatusOr<CgroupRunResult> Render(const std::string& store, const std::string& name, uint64_t limit,
                                   double* seconds) {
    CgroupRunOptions o;
    o.limit_bytes = limit;
    o.drop_page_cache = true;
    o.stderr_path = dir_ + "/" + name + ".log";
    made_.push_back(o.stderr_path);
    made_.push_back(dir_ + "/" + name + ".exr");
    const auto t0 = std::chrono::steady_clock::now();
    auto run = RunInMemoryCgroup({VOX_RENDER_BIN, store, "--cam", dir_ + "/cam.json", "--scene",
                                  dir_ + "/scene.json", "--threads", "2", "-o",
                                  dir_ + "/" + name + ".exr", "--quiet"},
                                 o);
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (run.ok())
      printf("%s (limit %llu MiB): %.1f s, %s\n", name.c_str(), (unsigned long long)(limit / kMiB),
             *seconds, run->Describe().c_str());
    return run;
  }

  std::string dir_;
  std::vector<std::string> made_;
};

TEST_F(OutOfCoreLong, SphereFullViewIn256MiBIsTheUnlimitedImage) {
  VOX_REQUIRE_MEMORY_CGROUP();
  std::string store = Env("VOX_LONG_STORE_8192");
  if (store.empty()) {
    store = dir_ + "/sphere8192.store";
    Generate(store, 8192, 3.0, 0);
    if (HasFatalFailure()) return;
  }
  double free_s = 0, lim_s = 0;
  auto free_run = Render(store, "unlimited", 0, &free_s);
  ASSERT_TRUE(free_run.ok()) << free_run.status().ToString();
  ASSERT_EQ(free_run->exit_code, 0) << ReadAll(dir_ + "/unlimited.log");
  const uint64_t limit = 256 * kMiB;
  auto run = Render(store, "limited", limit, &lim_s);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  EXPECT_FALSE(run->oom_killed) << run->Describe();
  ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(dir_ + "/limited.log");
  EXPECT_LE(run->peak_bytes, limit);
  printf("256 MiB / unlimited cold wall time: %.2fx\n", lim_s / free_s);
  auto a = ReadExr(dir_ + "/unlimited.exr");
  auto b = ReadExr(dir_ + "/limited.exr");
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->pixels.size(), b->pixels.size());
  for (const auto& [channel, pa] : a->pixels) {
    ASSERT_EQ(b->pixels.count(channel), 1u) << channel;
    const std::vector<float>& pb = b->pixels.at(channel);
    ASSERT_EQ(pa.size(), pb.size());
    size_t differ = 0;
    for (size_t i = 0; i < pa.size(); ++i) differ += std::memcmp(&pa[i], &pb[i], sizeof(float)) != 0;
    EXPECT_EQ(differ, 0u) << "channel " << channel;
  }
}

TEST_F(OutOfCoreLong, StoreLargerThanRamRendersIn1GiB) {
  VOX_REQUIRE_MEMORY_CGROUP();
  const uint64_t size = std::stoull(Env("VOX_LONG_BIG_SIZE", "32768"));
  // A band-b shell of the unit sphere (radius 15/32 of the grid) holds about
  // 4 pi r^2 b voxels at about 1 byte each on disk (vox-gen's 8192^3 sphere,
  // band 3: 549 MiB, 1.03 B per voxel); the band is the smallest that passes
  // MemTotal by 10% (32768^3 with 23.5 GiB of RAM: band 10, about 30 GB,
  // over an hour to write on 2 cores).
  const double r = double(size) * 15 / 32;
  const uint64_t ram = MemTotalBytes();
  double band = 3;
  if (!Env("VOX_LONG_BIG_BAND").empty()) {
    band = std::stod(Env("VOX_LONG_BIG_BAND"));
  } else {
    while (4 * M_PI * r * r * band * 1.0 < 1.1 * double(ram)) band += 1;
  }
  const std::string store = dir_ + "/big.store";
  const uint64_t limit = 1024 * kMiB;
  Generate(store, size, band, limit);
  if (HasFatalFailure()) return;
  const uint64_t bytes = DirBytes(store);
  RecordProperty("store_mib", std::to_string(bytes / kMiB));
  if (Env("VOX_LONG_BIG_SIZE").empty() && Env("VOX_LONG_BIG_BAND").empty()) {
    EXPECT_GT(bytes, ram) << "the store should be larger than RAM";
  }
  printf("store %llu MiB, RAM %llu MiB\n", (unsigned long long)(bytes / kMiB),
         (unsigned long long)(ram / kMiB));

  double secs = 0;
  auto run = Render(store, "big", limit, &secs);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  EXPECT_FALSE(run->oom_killed) << run->Describe();
  ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(dir_ + "/big.log");
  EXPECT_LE(run->peak_bytes, limit);

  // The silhouette against the exact unit sphere: a pixel's centre ray that
  // passes inside it by more than two voxels must hit, one that passes
  // outside by more than two voxels must miss.
  auto img = ReadExr(dir_ + "/big.exr");
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  auto opened = Store::Open(store, {});
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  const double margin = 2 * (*opened)->meta().voxel_size;
  const int w = img->info.width, h = img->info.height;
  const std::vector<float>& alpha = img->pixels.at("A");
  const double tan_half = std::tan(20.0 * M_PI / 180.0);
  size_t wrong = 0, checked = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // Camera at (0,0,3) looking down -z, y up; pixel centres.
      const double u = (2 * (x + 0.5) / w - 1) * tan_half, v = (1 - 2 * (y + 0.5) / h) * tan_half;
      const double len = std::sqrt(u * u + v * v + 1);
      // Distance from the sphere's centre to the ray from (0,0,3) along (u,v,-1)/len.
      const double t = 3.0 / len;  // projection of the centre on the ray
      const double px = u / len * t, py = v / len * t, pz = 3 - t / len;
      const double d = std::sqrt(px * px + py * py + pz * pz);
      if (std::abs(d - 1.0) <= margin) continue;
      ++checked;
      wrong += (d < 1.0) != (alpha[size_t(y) * w + x] > 0.0f);
    }
  printf("silhouette: %zu of %zu pixels away from the edge disagree with the exact sphere\n", wrong,
         checked);
  EXPECT_EQ(wrong, 0u);
  EXPECT_GT(checked, size_t(w) * h * 9 / 10);
}

}  // namespace
}  // namespace vox::testing

// Long out-of-core checks (label long; need root and a writable memory cgroup,
// skipped otherwise), as a batch job with a memory limit runs vox:
//  - the full view of an 8192^3 sphere store in a 256 MiB cgroup, cold: not
//    killed, peak within the limit, every EXR channel bit-identical to the
//    unlimited cold run (wall times of both are printed, not judged: the
//    ratio is a benchmark, docs/scale.md);
//  - a store larger than this machine's RAM, pyramid included, written by
//    vox-gen in a 1 GiB cgroup, and its full view (level of detail, the
//    default) and a close-up rendered cold in a 1 GiB cgroup: none is
//    killed, every peak stays within the limit, the full view's silhouette
//    is the sphere's wherever the exact sphere passes more than a pixel (and
//    two voxels) from the pixel's centre ray, the close-up is covered and
//    bit-identical with its --lod 0 render. Figures: docs/scale.md.
// Environment: VOX_LONG_STORE_8192 names an existing 8192^3 sphere store to
// use (else vox-gen writes one, about 550 MiB); VOX_LONG_BIG_STORE an
// existing big store (a vox-gen sphere or rough shell of the unit sphere);
// else VOX_LONG_BIG_SHAPE (default rough: jittered normals and speckled
// colours, about 10 bytes per voxel with the pyramid, against the sphere's
// 1.4), VOX_LONG_BIG_SIZE (default 16384) and VOX_LONG_BIG_BAND (default:
// the smallest band whose estimated store exceeds MemTotal by 10%: band 4,
// about 30 GB, 30-40 minutes on 2 cores) choose what vox-gen writes; VOX_LONG_DIR holds the
// stores (default: the test's temp dir; several tens of GB).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
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

// The figures docs/scale.md records from a frame's --stats: bricks paged in
// (every level) and bytes the process read.
std::string Figures(const std::string& stats_path) {
  const std::string s = ReadAll(stats_path);
  auto field = [&](const std::string& key) -> std::string {
    const size_t k = s.find("\"" + key + "\"");
    if (k == std::string::npos) return "?";
    size_t b = s.find(':', k) + 1, e = s.find_first_of(",}\n", b);
    return s.substr(b, e - b);
  };
  const std::string lod = field("bricks_paged_total");
  return "bricks " + (lod != "?" ? lod : field("misses")) + ", read_bytes " + field("read_bytes");
}

// Every channel of two EXRs, bit for bit: the number of differing values.
size_t DifferingValues(const std::string& a_path, const std::string& b_path) {
  auto a = ReadExr(a_path);
  auto b = ReadExr(b_path);
  EXPECT_TRUE(a.ok() && b.ok());
  if (!a.ok() || !b.ok() || a->pixels.size() != b->pixels.size()) return SIZE_MAX;
  size_t differ = 0;
  for (const auto& [channel, pa] : a->pixels) {
    if (b->pixels.count(channel) != 1) return SIZE_MAX;
    const std::vector<float>& pb = b->pixels.at(channel);
    if (pa.size() != pb.size()) return SIZE_MAX;
    for (size_t i = 0; i < pa.size(); ++i) differ += std::memcmp(&pa[i], &pb[i], sizeof(float)) != 0;
  }
  return differ;
}

class OutOfCoreLong : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = Env("VOX_LONG_DIR", ::testing::TempDir() + "vox_ooc_long_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    std::ofstream(dir_ + "/cam.json")
        << R"({"position":[0,0,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":40,)"
           R"("width":1024,"height":1024,"projection":"perspective"})";
    std::ofstream(dir_ + "/cam_closeup.json")
        << R"({"position":[0,0,1.05],"look_at":[0,0,0.9],"up":[0,1,0],"fov_deg":20,)"
           R"("width":1024,"height":1024,"projection":"perspective"})";
    std::ofstream(dir_ + "/scene.json")
        << R"({"lights":[{"type":"directional","direction":[-1,-1,-1],"intensity":1.0,"shadows":false}]})";
  }
  void TearDown() override {
    for (const std::string& p : made_) fs::remove_all(p);
  }

  // vox-gen `shape` of `size` and `band` into `store`, in a cgroup of
  // `limit` bytes; `lod`: with its pyramid.
  void Generate(const std::string& store, uint64_t size, double band, uint64_t limit,
                const std::string& shape = "sphere", bool lod = false) {
    made_.push_back(store);
    CgroupRunOptions o;
    o.limit_bytes = limit;
    o.stderr_path = store + ".gen.log";
    made_.push_back(o.stderr_path);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::string> argv{VOX_GEN_BIN, shape,  store,   "--size", std::to_string(size),
                                  "--band",    std::to_string(band), "--force", "--quiet"};
    if (!lod) argv.push_back("--no-lod");
    auto run = RunInMemoryCgroup(argv, o);
    ASSERT_TRUE(run.ok()) << run.status().ToString();
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    printf("vox-gen %s --size %llu --band %g: %.0f s, %s, store %llu MiB\n", shape.c_str(),
           (unsigned long long)size, band, secs, run->Describe().c_str(),
           (unsigned long long)(fs::exists(store) ? DirBytes(store) / kMiB : 0));
    EXPECT_FALSE(run->oom_killed) << run->Describe();
    ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(o.stderr_path);
    if (limit > 0) {
      EXPECT_LE(run->peak_bytes, limit);
    }
  }

  // One cold frame of `store` in a cgroup of `limit` bytes (0: unlimited),
  // from `cam` (default: the full view), with `extra` flags.
  StatusOr<CgroupRunResult> Render(const std::string& store, const std::string& name, uint64_t limit,
                                   double* seconds, const std::string& cam = "cam.json",
                                   const std::vector<std::string>& extra = {}) {
    CgroupRunOptions o;
    o.limit_bytes = limit;
    o.drop_page_cache = true;
    o.stderr_path = dir_ + "/" + name + ".log";
    made_.push_back(o.stderr_path);
    made_.push_back(dir_ + "/" + name + ".exr");
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::string> argv{VOX_RENDER_BIN, store, "--cam", dir_ + "/" + cam, "--scene",
                                  dir_ + "/scene.json", "--threads", "2", "-o",
                                  dir_ + "/" + name + ".exr", "--stats", dir_ + "/" + name + ".json",
                                  "--quiet"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    made_.push_back(dir_ + "/" + name + ".json");
    auto run = RunInMemoryCgroup(argv, o);
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (run.ok())
      printf("%s (limit %llu MiB): %.1f s, %s; stats %s\n", name.c_str(),
             (unsigned long long)(limit / kMiB), *seconds, run->Describe().c_str(),
             Figures(dir_ + "/" + name + ".json").c_str());
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
  const uint64_t limit = 1024 * kMiB;
  const uint64_t ram = MemTotalBytes();
  std::string store = Env("VOX_LONG_BIG_STORE");
  if (store.empty()) {
    const std::string shape = Env("VOX_LONG_BIG_SHAPE", "rough");
    const uint64_t size = std::stoull(Env("VOX_LONG_BIG_SIZE", "16384"));
    // A band-b shell of the unit sphere (radius 15/32 of the grid) holds
    // about 4 pi r^2 b voxels; with its pyramid a rough store takes about 10
    // bytes per voxel on disk, a sphere store 1.4 (vox-gen at 2048^3: 352 and
    // 64 MiB for 34.6 M voxels). The band is the smallest that passes
    // MemTotal by 10% (16384^3 rough with 23.5 GiB of RAM: band 4, ~30 GB).
    const double r = double(size) * 15 / 32, per_voxel = shape == "rough" ? 10.0 : 1.4;
    double band = 3;
    if (!Env("VOX_LONG_BIG_BAND").empty()) {
      band = std::stod(Env("VOX_LONG_BIG_BAND"));
    } else {
      while (4 * M_PI * r * r * band * per_voxel < 1.1 * double(ram)) band += 1;
    }
    store = dir_ + "/big.store";
    Generate(store, size, band, limit, shape, /*lod=*/true);
    if (HasFatalFailure()) return;
  }
  const uint64_t bytes = DirBytes(store);
  RecordProperty("store_mib", std::to_string(bytes / kMiB));
  printf("store %s: %llu MiB, RAM %llu MiB\n", store.c_str(), (unsigned long long)(bytes / kMiB),
         (unsigned long long)(ram / kMiB));
  if (Env("VOX_LONG_BIG_SIZE").empty() && Env("VOX_LONG_BIG_BAND").empty()) {
    EXPECT_GT(bytes, ram) << "the store should be larger than RAM";
  }

  // The close-up: covered, and bit for bit the exact frame (--lod 0).
  for (const char* mode : {"closeup", "closeup_exact"}) {
    double secs = 0;
    auto run = Render(store, mode, limit, &secs, "cam_closeup.json",
                      std::string(mode) == "closeup" ? std::vector<std::string>{}
                                                     : std::vector<std::string>{"--lod", "0"});
    ASSERT_TRUE(run.ok()) << run.status().ToString();
    EXPECT_FALSE(run->oom_killed) << run->Describe();
    ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(dir_ + "/" + mode + ".log");
    EXPECT_LE(run->peak_bytes, limit);
  }
  EXPECT_EQ(DifferingValues(dir_ + "/closeup.exr", dir_ + "/closeup_exact.exr"), 0u);
  auto close = ReadExr(dir_ + "/closeup.exr");
  ASSERT_TRUE(close.ok());
  for (float a : close->pixels.at("A")) ASSERT_EQ(a, 1.0f) << "the close-up sees only the surface";

  double secs = 0;
  auto run = Render(store, "big", limit, &secs);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  EXPECT_FALSE(run->oom_killed) << run->Describe();
  ASSERT_EQ(run->exit_code, 0) << run->Describe() << "\n" << ReadAll(dir_ + "/big.log");
  EXPECT_LE(run->peak_bytes, limit);

  // The silhouette against the exact unit sphere: a pixel's centre ray that
  // passes inside it by more than a margin must hit, one that passes outside
  // by more must miss. The margin: two voxels, or the pixel's footprint at
  // the silhouette (about 2.83 from the camera) where that is larger, since
  // the default frame stops at cells about a pixel wide there.
  auto img = ReadExr(dir_ + "/big.exr");
  ASSERT_TRUE(img.ok()) << img.status().ToString();
  auto opened = Store::Open(store, {});
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  const double pixel = std::sqrt(8.0) * 2 * std::tan(20.0 * M_PI / 180.0) / img->info.width;
  const double margin = std::max(2 * (*opened)->meta().voxel_size, pixel);
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

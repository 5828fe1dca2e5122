// vox-probe --lod end to end on a vox-gen store with its pyramid: a tiny cone
// answers exactly as without --lod, a wide one stops at coarse cells never
// later than the exact hit and never finer than its cone allows, and bad
// input names the flag.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "tools/gen/generate.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

struct Result {
  int exit_code = -1;
  std::string out, err;
};

Result RunProbe(const fs::path& dir, const std::string& args, const std::string& input) {
  std::ofstream(dir / "in.txt") << input;
  const std::string cmd = std::string(VOX_PROBE_BIN) + " " + args + " < " + (dir / "in.txt").string() +
                          " > " + (dir / "out.txt").string() + " 2> " + (dir / "err.txt").string();
  const int status = std::system(cmd.c_str());
  Result r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const fs::path& p) {
    std::ifstream f(p);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  r.out = slurp(dir / "out.txt");
  r.err = slurp(dir / "err.txt");
  return r;
}

std::vector<std::string> Lines(const std::string& s) {
  std::vector<std::string> v;
  std::istringstream in(s);
  for (std::string l; std::getline(in, l);) v.push_back(l);
  return v;
}

class ProbeLod : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vox_probe_lod_" + std::to_string(getpid()));
    fs::create_directories(dir_);
    for (bool lod : {true, false}) {
      gen::GenerateOptions o;
      o.shape = "sphere";
      o.size = 256;
      o.output = (dir_ / (lod ? "s" : "n")).string();
      o.threads = 2;
      o.lod = lod;
      auto st = gen::Generate(o);
      ASSERT_TRUE(st.ok()) << st.status().ToString();
    }
    // Rays from outside towards points near the sphere (index space: centred on 0, radius 120).
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> u(-1, 1);
    std::ostringstream rays;
    for (int i = 0; i < 400; ++i) {
      glm::dvec3 target(u(rng) * 130, u(rng) * 130, u(rng) * 130);
      glm::dvec3 dir(u(rng), u(rng), u(rng));
      dir /= std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
      const glm::dvec3 o = target - 400.0 * dir;
      char line[256];
      snprintf(line, sizeof line, "%a %a %a %a %a %a\n", o.x, o.y, o.z, dir.x, dir.y, dir.z);
      rays << line;
    }
    rays_ = rays.str();
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
  std::string rays_;
};

TEST_F(ProbeLod, TinyConeAnswersExactly) {
  Result exact = RunProbe(dir_, (dir_ / "s").string(), rays_);
  ASSERT_EQ(exact.exit_code, 0) << exact.err;
  Result lod = RunProbe(dir_, (dir_ / "s").string() + " --lod 1 --cone-rad 1e-9", rays_);
  ASSERT_EQ(lod.exit_code, 0) << lod.err;
  EXPECT_EQ(lod.out, exact.out);
  EXPECT_NE(exact.out.find("hit"), std::string::npos);
}

TEST_F(ProbeLod, WideConeStopsAtCoarseCellsNoLaterThanTheExactHit) {
  Result exact = RunProbe(dir_, (dir_ / "s").string(), rays_);
  const double rad = 0.02;  // 8 voxels at t = 400: level 3 near the sphere
  Result lod = RunProbe(dir_, (dir_ / "s").string() + " --lod 1 --cone-rad 0.02 --stats", rays_);
  ASSERT_EQ(lod.exit_code, 0) << lod.err;
  const auto a = Lines(exact.out), b = Lines(lod.out);
  ASSERT_EQ(a.size(), b.size());
  int coarse = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (b[i].rfind("lod ", 0) != 0) continue;
    ++coarse;
    int level = 0;
    long long x, y, z;
    double t = 0;
    ASSERT_EQ(std::sscanf(b[i].c_str(), "lod %d %lld %lld %lld %lf", &level, &x, &y, &z, &t), 5) << b[i];
    EXPECT_GE(level, 1);
    EXPECT_GE(rad * t, std::ldexp(1.0, level) * (1 - 1e-9)) << b[i];  // cone >= cell (F = 1)
    EXPECT_EQ(x % (1LL << level), ((-128 % (1LL << level)) + (1LL << level)) % (1LL << level))
        << "a cell's first voxel is aligned to its size in grid coordinates: " << b[i];
    double te = 0;
    long long ex, ey, ez;
    if (std::sscanf(a[i].c_str(), "hit %lld %lld %lld %lf", &ex, &ey, &ez, &te) == 4) {
      EXPECT_LE(t, te + 1e-9) << b[i] << " vs " << a[i];
    }
  }
  EXPECT_GT(coarse, 50);
  EXPECT_NE(lod.err.find("lod stops by level"), std::string::npos);
}

TEST_F(ProbeLod, BadInputNamesTheFlag) {
  for (const char* bad : {"0", "-2", "nan", "inf", "x"}) {
    Result r = RunProbe(dir_, (dir_ / "s").string() + " --lod " + bad + " --cone-rad 0.1", rays_);
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.err;  // a bad flag value
    EXPECT_NE(r.err.find("--lod"), std::string::npos) << r.err;
  }
  Result r = RunProbe(dir_, (dir_ / "n").string() + " --lod 1 --cone-rad 0.1", rays_);
  EXPECT_EQ(r.exit_code, 1) << r.err;  // --lod without a pyramid: the store cannot serve it
  EXPECT_NE(r.err.find("--lod"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--add-lod"), std::string::npos) << r.err;
  r = RunProbe(dir_, (dir_ / "s").string() + " --lod 1", rays_);
  EXPECT_NE(r.err.find("--cone-rad"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace vox

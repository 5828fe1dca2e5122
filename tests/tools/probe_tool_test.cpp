// vox-probe end to end: its output format, its errors, and its answers from a
// store equal those from the same voxels in memory.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cmath>
#include <map>
#include <random>
#include <vector>
#include <sstream>
#include <tuple>
#include <string>

#include "core/core.h"
#include "core/octree.h"
#include "core/ray_text.h"
#include "core/shapes.h"
#include "core/tracer.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox {
namespace {

struct Result {
  int exit_code = -1;
  std::string out, err;
};

// Runs vox-probe with `args`, feeding `input` on stdin.
Result RunProbe(const std::string& args, const std::string& input) {
  auto dir = std::filesystem::temp_directory_path() / ("vox_probe_test_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "in.txt") << input;
  std::string cmd = std::string(VOX_PROBE_BIN) + " " + args + " < " + (dir / "in.txt").string() +
                    " > " + (dir / "out.txt").string() + " 2> " + (dir / "err.txt").string();
  int status = std::system(cmd.c_str());
  Result r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const std::filesystem::path& p) {
    std::ifstream f(p);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  r.out = slurp(dir / "out.txt");
  r.err = slurp(dir / "err.txt");
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);  // nothing left in the temporary directory
  return r;
}

TEST(ProbeTool, HitsMissesAndHexFloats) {
  // sphere:64: shell of radius 25.6 around (32,32,32).
  Result r = RunProbe("--generate sphere:64",
                      "32.3 32.7 -10 0 0 1\n0x1.02p+5 32.5 100 0 0 -0x1p+0\n0 0 0 -1 0 0\n");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "hit 32 32 6 16\nhit 32 32 57 42\nmiss\n");
}

TEST(ProbeTool, MalformedLinesAreNamedAndKeepTheOutputAligned) {
  Result r = RunProbe("--generate sphere:64", "1 2 3\n32.3 32.7 -10 0 0 1\n1 2 3 nan 0 0\n1 2 3 0 0 0\n");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.out, "error\nhit 32 32 6 16\nerror\nerror\n");
  EXPECT_NE(r.err.find("stdin line 1: expected 6 numbers"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("stdin line 3: ray has a non-finite component"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("stdin line 4: ray direction is zero"), std::string::npos) << r.err;
}

// A ray the tracer refuses is described as it was given (index
// coordinates), not shifted into the store's grid.
TEST(ProbeTool, RefusedRaysAreNamedInIndexCoordinates) {
  auto dir = std::filesystem::temp_directory_path() / ("vox_probe_nan_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  StoreMeta meta;
  meta.levels = 6;
  meta.brick_level = 3;
  meta.origin = {-64, 10, 1000};
  meta.source_file = "one voxel";
  auto w = StoreWriter::Create(dir.string(), meta, WriteOptions{});
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  BrickVoxel v;
  ASSERT_TRUE((*w)->AddBrick({1, 1, 1}, {v}).ok());
  ASSERT_TRUE((*w)->Finish().ok());
  Result r = RunProbe(dir.string(), "1 2 3 nan 0 0\n1 2 3 0 0 0\n");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.out, "error\nerror\n");
  EXPECT_NE(r.err.find("stdin line 1: ray has a non-finite component: origin (1, 2, 3) "
                       "direction (nan, 0, 0)"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("stdin line 2: ray direction is zero"), std::string::npos) << r.err;
  std::filesystem::remove_all(dir);
}

TEST(ProbeTool, BadFlagsAndMissingStore) {
  EXPECT_EQ(RunProbe("--generate blob:64", "").exit_code, 2);
  EXPECT_EQ(RunProbe("--generate sphere:64 --split 3+4", "").exit_code, 2);
  Result r = RunProbe("/nonexistent/store", "");
  EXPECT_EQ(r.exit_code, 1);  // a failure, as vox-render's and vox-info's
  EXPECT_NE(r.err.find("/nonexistent/store"), std::string::npos) << r.err;
}

// The tracer behind each --tracer, by comparing vox-probe's answers with the
// tracers themselves on the same tree: by default AutoTracer<double>, the
// type vox-render traces with (render/renderer.h RenderTracer), with
// --tracer long-double AutoTracer<long double>. Rays from far away with
// tiny components, where a double and a long-double set-up can part
// (tests/core hold both to the exact reference).
TEST(ProbeTool, TracerFlagChoosesTheRendersOrTheLongDoubleTracer) {
  for (const char* shape : {"sphere:256", "corner:40"}) {
    SCOPED_TRACE(shape);
    auto vol = GenerateShape(shape);
    ASSERT_TRUE(vol.ok());
    const int levels = vol->levels;
    auto tree = MemoryOctree::Build(vol->voxels, levels, std::max(1, levels - 5));
    ASSERT_TRUE(tree.ok());
    const int n1 = DefaultFirstStepLevels(levels);
    auto render = AutoTracer<double>::Create((*tree)->view(), n1);
    auto long_double = AutoTracer<long double>::Create((*tree)->view(), n1);
    ASSERT_TRUE(render.ok() && long_double.ok());
    std::mt19937_64 rng(27);
    std::uniform_real_distribution<double> u(-1, 1);
    const double g = std::ldexp(1.0, levels);
    std::vector<Ray> rays;
    std::string input;
    for (int i = 0; i < 400; ++i) {
      const LeafPoint& v = vol->voxels[rng() % vol->voxels.size()];
      const glm::dvec3 target(v.x + 0.5 + 0.5 * u(rng), v.y + 0.5 + 0.5 * u(rng), v.z + 0.5 + 0.5 * u(rng));
      glm::dvec3 dir(u(rng), u(rng), u(rng));
      dir[rng() % 3] *= std::ldexp(1.0, -int(rng() % 60));  // tiny components
      const double far = g * std::ldexp(1.0, int(rng() % 20));
      Ray r{target - far * dir, dir};
      rays.push_back(r);
      char line[256];
      std::snprintf(line, sizeof line, "%a %a %a %a %a %a\n", r.origin.x, r.origin.y, r.origin.z,
                    r.dir.x, r.dir.y, r.dir.z);
      input += line;
    }
    auto expect = [&](const auto& tracer, const std::string& flags) {
      Result res = RunProbe(std::string("--generate ") + shape + flags, input);
      ASSERT_EQ(res.exit_code, 0) << flags << ": " << res.err;
      std::istringstream out(res.out);
      std::string line;
      for (const Ray& r : rays) {
        ASSERT_TRUE(std::getline(out, line)) << flags;
        auto h = tracer.FirstHit(r);
        ASSERT_TRUE(h.ok());
        EXPECT_EQ(line, FormatHitLine(h->has_value() ? &(*h)->voxel : nullptr,
                                      h->has_value() ? (*h)->t : 0.0))
            << flags;
      }
    };
    expect(*render, "");
    expect(*render, " --tracer render");
    expect(*long_double, " --tracer long-double");
    int differ = 0;
    for (const Ray& r : rays) {
      auto a = render->FirstHit(r), b = long_double->FirstHit(r);
      differ += a.ok() && b.ok() && (a->has_value() != b->has_value() ||
                                     (a->has_value() && ((*a)->voxel != (*b)->voxel || (*a)->t != (*b)->t)));
    }
    std::printf("%s: %d of %zu rays answered differently by the two tracers\n", shape, differ,
                rays.size());
  }
  Result bad = RunProbe("--generate sphere:64 --tracer exact", "");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--tracer 'exact': expected render or long-double"), std::string::npos)
      << bad.err;
}

TEST(ProbeTool, StoreAnswersEqualMemoryAnswersAtEverySplit) {
  auto vol = GenerateShape("torus:128");
  ASSERT_TRUE(vol.ok());
  auto dir = std::filesystem::temp_directory_path() / ("vox_probe_store_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  StoreMeta meta;
  meta.levels = vol->levels;
  meta.brick_level = 3;
  meta.origin = {-64, 10, 1000};  // probe coordinates = grid + origin
  meta.source_file = "torus:128";
  auto w = StoreWriter::Create(dir.string(), meta, WriteOptions{});
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  std::map<std::tuple<uint64_t, uint64_t, uint64_t>, std::vector<BrickVoxel>> bricks;
  const int sub = meta.levels - meta.brick_level;
  for (const LeafPoint& p : vol->voxels) {
    BrickVoxel v;
    v.x = uint32_t(p.x & ((1u << sub) - 1));
    v.y = uint32_t(p.y & ((1u << sub) - 1));
    v.z = uint32_t(p.z & ((1u << sub) - 1));
    bricks[{p.x >> sub, p.y >> sub, p.z >> sub}].push_back(v);
  }
  for (auto& [c, vs] : bricks)
    ASSERT_TRUE((*w)->AddBrick({std::get<0>(c), std::get<1>(c), std::get<2>(c)}, vs).ok());
  ASSERT_TRUE((*w)->Finish().ok());

  // Rays in probe space over the store, and the same rays shifted into grid
  // space over the generated volume.
  std::string store_rays, grid_rays;
  for (int i = 0; i < 200; ++i) {
    double x = 3 + (i * 7919) % 120 + 0.37, y = 5 + (i * 104729) % 118 + 0.61;
    double dx = ((i % 7) - 3) * 0.05, dy = ((i % 5) - 2) * 0.07;
    char buf[200];
    std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g %.17g %.17g 1\n", x, y, -20.0, dx, dy);
    grid_rays += buf;
    std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g %.17g %.17g 1\n", x - 64, y + 10, -20.0 + 1000,
                  dx, dy);
    store_rays += buf;
  }
  Result mem = RunProbe("--generate torus:128", grid_rays);
  ASSERT_EQ(mem.exit_code, 0) << mem.err;
  EXPECT_NE(mem.out.find("hit"), std::string::npos);
  for (const char* split : {"--split 7", "--split 3+4", "--split 5+2", "--single-step"}) {
    Result st = RunProbe(dir.string() + " " + split, store_rays);
    ASSERT_EQ(st.exit_code, 0) << split << ": " << st.err;
    // Same hits, shifted by the origin; same t.
    std::istringstream a(mem.out), b(st.out);
    std::string la, lb;
    int lines = 0;
    while (std::getline(a, la) && std::getline(b, lb)) {
      ++lines;
      if (la == "miss") {
        EXPECT_EQ(lb, "miss") << split;
        continue;
      }
      long long i, j, k, i2, j2, k2;
      double t, t2;
      ASSERT_EQ(std::sscanf(la.c_str(), "hit %lld %lld %lld %lf", &i, &j, &k, &t), 4);
      ASSERT_EQ(std::sscanf(lb.c_str(), "hit %lld %lld %lld %lf", &i2, &j2, &k2, &t2), 4) << lb;
      EXPECT_EQ(i - 64, i2);
      EXPECT_EQ(j + 10, j2);
      EXPECT_EQ(k + 1000, k2);
      EXPECT_NEAR(t, t2, 1e-9 * (1 + t));
    }
    EXPECT_EQ(lines, 200);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace vox

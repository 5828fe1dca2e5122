// vox-gen and gen::Generate: the stores' voxels against a brute-force pass
// over every grid voxel, metadata and counts, outward normals, byte-identical
// reruns, and bad arguments / interruptions leaving no store.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <tuple>

#include <glm/geometric.hpp>

#include "core/octree.h"
#include "tools/gen/generate.h"
#include "tools/gen/shapes.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "storage/store_info.h"

namespace vox {
namespace {

namespace fs = std::filesystem;
using Ijk = std::tuple<int64_t, int64_t, int64_t>;

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "vox_gen_test_XXXXXX").string();
    path_ = mkdtemp(tmpl.data()) ? tmpl : "";
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string operator/(const std::string& n) const { return path_ + "/" + n; }
  const std::string& path() const { return path_; }
  // Entries of the directory (to see that nothing, not even a temp dir, is left).
  std::set<std::string> Entries() const {
    std::set<std::string> out;
    for (const auto& e : fs::directory_iterator(path_)) out.insert(e.path().filename().string());
    return out;
  }

 private:
  std::string path_;
};

struct StoredVoxel {
  uint32_t brick, payload;
};

// Walks the octree under `cell` (grid coordinates `base`, 2^size_log2 per axis).
Status Walk(Store& store, const CompactCell* pool, uint32_t cell, int size_log2, Ijk base,
            uint32_t brick, std::map<Ijk, StoredVoxel>* out) {
  const OctreeView v = store.view();
  const int child_log2 = size_log2 - 1;
  for (unsigned d = 0; d < 8; ++d) {
    ChildRef ref = ChildOf(pool[cell], d, v.levels - size_log2, v);
    if (ref.kind == ChildRef::kEmpty) continue;
    Ijk c{std::get<0>(base) + (int64_t(d & 1) << child_log2),
          std::get<1>(base) + (int64_t((d >> 1) & 1) << child_log2),
          std::get<2>(base) + (int64_t((d >> 2) & 1) << child_log2)};
    if (ref.kind == ChildRef::kPayload) {
      if (!out->emplace(c, StoredVoxel{brick, ref.index}).second)
        return InternalError("voxel listed twice");
    } else if (ref.kind == ChildRef::kBrick) {
      VOX_ASSIGN_OR_RETURN(BrickView b, store.FetchBrick(ref.index));
      VOX_RETURN_IF_ERROR(Walk(store, b.cells, 0, child_log2, c, ref.index, out));
    } else {
      VOX_RETURN_IF_ERROR(Walk(store, pool, ref.index, child_log2, c, brick, out));
    }
  }
  return OkStatus();
}

// The store's voxels in grid coordinates.
std::map<Ijk, StoredVoxel> ReadAll(Store& store) {
  std::map<Ijk, StoredVoxel> out;
  OctreeView v = store.view();
  Status s = Walk(store, v.top, 0, v.levels, Ijk{0, 0, 0}, kNoBrick, &out);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return out;
}

// The documented sphere, computed directly: grid voxel g is index g - N/2, the
// sphere has radius 15 N / 32 voxels about index 0, occupied: -band < d <= 0.
std::set<Ijk> BruteSphere(int64_t n, double band) {
  std::set<Ijk> out;
  const double r = double(n) * 15 / 32;
  for (int64_t x = 0; x < n; ++x)
    for (int64_t y = 0; y < n; ++y)
      for (int64_t z = 0; z < n; ++z) {
        double i = double(x - n / 2), j = double(y - n / 2), k = double(z - n / 2);
        double d = std::sqrt(i * i + j * j + k * k) - r;
        if (d > -band && d <= 0) out.insert({x, y, z});
      }
  return out;
}

gen::GenerateOptions Options(const std::string& shape, uint64_t size, const std::string& out) {
  gen::GenerateOptions o;
  o.shape = shape;
  o.size = size;
  o.output = out;
  o.threads = 2;
  return o;
}

std::string Slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Checks the store at `dir` against `expected` (grid coordinates): the voxel
// set, the metadata's counts and placement, and outward unit normals.
// `radial`: normals equal the direction from the centre (the plain sphere).
void CheckStore(const std::string& dir, const std::set<Ijk>& expected, uint64_t size,
                int brick_level, bool radial) {
  auto store = Store::Open(dir, OpenOptions());
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const StoreMeta& m = (*store)->meta();
  const int n = int(std::log2(double(size)));
  EXPECT_EQ(m.levels, n);
  EXPECT_EQ(m.brick_level, brick_level);
  EXPECT_EQ(m.grid_class, GridClass::kLevelSet);
  EXPECT_TRUE(m.has_normal);
  EXPECT_EQ(m.origin, glm::i64vec3(-int64_t(size / 2)));
  EXPECT_DOUBLE_EQ(m.voxel_size, 32.0 / (15.0 * double(size)));
  EXPECT_DOUBLE_EQ(m.index_to_world[0][0], m.voxel_size);
  EXPECT_DOUBLE_EQ(m.index_to_world[3][0], 0.0);  // index 0 is world 0

  auto got = ReadAll(**store);
  std::set<Ijk> got_set;
  for (const auto& [g, v] : got) got_set.insert(g);
  EXPECT_EQ(got_set.size(), expected.size());
  EXPECT_TRUE(got_set == expected) << "voxel sets differ";
  EXPECT_EQ(m.voxel_count, expected.size());

  std::set<Ijk> bricks;
  glm::i64vec3 lo(INT64_MAX), hi(INT64_MIN);
  const int depth = n - brick_level;
  for (const Ijk& g : expected) {
    bricks.insert({std::get<0>(g) >> depth, std::get<1>(g) >> depth, std::get<2>(g) >> depth});
    glm::i64vec3 v(std::get<0>(g), std::get<1>(g), std::get<2>(g));
    lo = glm::min(lo, v);
    hi = glm::max(hi, v);
  }
  if (depth > 0) {
    EXPECT_EQ(m.brick_count, bricks.size());
  }
  if (!expected.empty()) {
    EXPECT_EQ(m.bbox_min, lo + m.origin);
    EXPECT_EQ(m.bbox_max, hi + m.origin);
  }

  // Normals: unit, pointing away from the centre (index 0).
  size_t inward = 0;
  for (const auto& [g, v] : got) {
    auto a = (*store)->Attributes(v.brick, v.payload);
    ASSERT_TRUE(a.ok()) << a.status().ToString();
    glm::dvec3 p(double(std::get<0>(g)) - double(size / 2), double(std::get<1>(g)) - double(size / 2),
                 double(std::get<2>(g)) - double(size / 2));
    EXPECT_NEAR(glm::length(a->normal), 1.0, 1e-3);
    if (p == glm::dvec3(0)) continue;
    if (glm::dot(glm::dvec3(a->normal), p) <= 0) ++inward;
    if (radial) {
      EXPECT_LT(glm::length(glm::dvec3(a->normal) - glm::normalize(p)), 1e-3);
    }
  }
  EXPECT_EQ(inward, 0u);

  // vox-info's figures: the same counts, every brick decodes.
  auto info = InspectStore(dir, /*verify_bricks=*/true);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_TRUE(info->verified);
  EXPECT_EQ(info->meta.voxel_count, expected.size());
  EXPECT_EQ(info->meta.brick_count, m.brick_count);
}

TEST(GenSphere, VoxelsEqualTheBruteForceBandAtEverySplit) {
  struct Case {
    uint64_t size;
    std::string levels;
    double band;
    int brick_level;
  };
  for (const Case& c : {Case{64, "auto", 3.0, 1}, Case{64, "3+3", 3.0, 3}, Case{32, "2+3", 1.5, 2},
                        Case{16, "auto", 3.0, 1}, Case{32, "5+0", 3.0, 5},  // top only
                        Case{8, "auto", 0.7, 1}, Case{64, "1+5", 40.0, 1}}) {
    SCOPED_TRACE("size " + std::to_string(c.size) + " levels " + c.levels + " band " +
                 std::to_string(c.band));
    TempDir t;
    gen::GenerateOptions o = Options("sphere", c.size, t / "s");
    o.levels = c.levels;
    o.band = c.band;
    auto st = gen::Generate(o);
    ASSERT_TRUE(st.ok()) << st.status().ToString();
    std::set<Ijk> expected = BruteSphere(int64_t(c.size), c.band);
    ASSERT_FALSE(expected.empty());
    EXPECT_EQ(st->voxels, expected.size());
    CheckStore(t / "s", expected, c.size, c.brick_level, /*radial=*/true);
  }
}

TEST(GenBumpy, NoOccupiedVoxelIsSkippedAndNormalsPointOutward) {
  TempDir t;
  auto st = gen::Generate(Options("bumpy", 64, t / "b"));
  ASSERT_TRUE(st.ok()) << st.status().ToString();
  // The shape's own distance at every grid voxel: the pruning never drops one.
  auto shape = gen::MakeShape("bumpy", 64);
  ASSERT_TRUE(shape.ok());
  std::set<Ijk> expected;
  size_t off_sphere = 0;
  for (int64_t x = 0; x < 64; ++x)
    for (int64_t y = 0; y < 64; ++y)
      for (int64_t z = 0; z < 64; ++z) {
        glm::dvec3 p(double(x - 32), double(y - 32), double(z - 32));
        double d = (*shape)->Distance(p);
        if (d > -3 && d <= 0) {
          expected.insert({x, y, z});
          // Displaced: not the plain sphere's band everywhere.
          double ds = glm::length(p) - 30.0;
          if (!(ds > -3 && ds <= 0)) ++off_sphere;
        }
      }
  EXPECT_GT(off_sphere, expected.size() / 50);
  CheckStore(t / "b", expected, 64, 1, /*radial=*/false);
}

TEST(GenRough, TheSpheresVoxelsWithJitteredNormalsAndColoursInABiggerStore) {
  TempDir t;
  auto sphere = gen::Generate(Options("sphere", 256, t / "s"));
  auto rough = gen::Generate(Options("rough", 256, t / "r"));
  ASSERT_TRUE(sphere.ok() && rough.ok());
  EXPECT_EQ(rough->voxels, sphere->voxels);
  EXPECT_EQ(rough->bricks, sphere->bricks);
  // Normals: unit, outward, not the sphere's (tilted by about 20 degrees, at most 37).
  auto shape = gen::MakeShape("rough", 256);
  ASSERT_TRUE(shape.ok());
  double min_cos = 1, sum_cos = 0;
  const int n = 1000;
  for (int i = 0; i < n; ++i) {
    const glm::dvec3 p(double(i % 37) - 18, double(i % 91) - 45, 120.0);
    const glm::dvec3 a = (*shape)->Normal(p), r = p / glm::length(p);
    EXPECT_NEAR(glm::length(a), 1.0, 1e-12);
    min_cos = std::min(min_cos, glm::dot(a, r));
    sum_cos += glm::dot(a, r);
  }
  // A jitter of at most 0.35 sqrt(3) tilts a unit normal by at most asin(0.606) = 37.3 degrees.
  EXPECT_GT(min_cos, 0.795);
  EXPECT_LT(sum_cos / n, 0.995);       // but tilted: not the sphere's normals
  auto bytes = [](const std::string& dir) {
    return std::filesystem::file_size(dir + "/bricks.vxb");
  };
  EXPECT_GT(bytes(t / "r"), 4 * bytes(t / "s")) << "jittered normals and speckles compress less";
  // Colours: in the store, speckled around a sand colour.
  auto store = Store::Open(t / "r", OpenOptions());
  ASSERT_TRUE(store.ok());
  EXPECT_TRUE((*store)->meta().has_color);
  EXPECT_FALSE(shape->get()->Color(glm::dvec3(1, 2, 3)) == shape->get()->Color(glm::dvec3(1, 2, 4)));
}

TEST(GenPair, TheSameTwoSpheresInEveryGrid) {
  // One sphere of radius 250 with band 3, counted voxel by voxel: each of the pair holds as many.
  uint64_t one = 0;
  for (int64_t x = -252; x <= 252; ++x)
    for (int64_t y = -252; y <= 252; ++y)
      for (int64_t z = -252; z <= 252; ++z) {
        const double d = std::sqrt(double(x * x + y * y + z * z)) - 250.0;
        one += d > -3 && d <= 0 ? 1 : 0;
      }
  TempDir t;
  uint64_t bricks = 0;
  for (uint64_t size : {uint64_t(2048), uint64_t(8192), uint64_t(65536)}) {
    SCOPED_TRACE(size);
    gen::GenerateOptions o = Options("pair", size, t / ("p" + std::to_string(size)));
    o.lod = false;
    auto st = gen::Generate(o);
    ASSERT_TRUE(st.ok()) << st.status().ToString();
    EXPECT_EQ(st->voxels, 2 * one);
    if (bricks == 0) bricks = st->bricks;
    EXPECT_EQ(st->bricks, bricks) << "the same bricks: the spheres lie at brick-aligned centres";
  }
  auto shape = gen::MakeShape("pair", 8192);
  ASSERT_TRUE(shape.ok());
  EXPECT_NEAR((*shape)->Distance(glm::dvec3(-2048 + 250, 0, 0)), 0.0, 1e-12);
  EXPECT_NEAR((*shape)->Distance(glm::dvec3(2048, 0, -250)), 0.0, 1e-12);
  EXPECT_NEAR((*shape)->Distance(glm::dvec3(0, 0, 0)), 2048.0 - 250.0, 1e-9);
  EXPECT_EQ((*shape)->Normal(glm::dvec3(2048, 0, -250)), glm::dvec3(0, 0, -1));
  EXPECT_FALSE(gen::MakeShape("pair", 1024).ok()) << "the spheres would not fit";
}

TEST(GenStore, SameOptionsGiveByteIdenticalStores) {
  TempDir t;
  for (const char* shape : {"sphere", "bumpy", "rough"}) {
    gen::GenerateOptions a = Options(shape, 128, t / (std::string(shape) + "1"));
    a.threads = 1;
    gen::GenerateOptions b = Options(shape, 128, t / (std::string(shape) + "2"));
    b.threads = 2;
    ASSERT_TRUE(gen::Generate(a).ok());
    ASSERT_TRUE(gen::Generate(b).ok());
    for (const char* f : {"index.vxi", "bricks.vxb"}) {
      std::string x = Slurp(a.output + "/" + f), y = Slurp(b.output + "/" + f);
      EXPECT_GT(x.size(), 100u);
      EXPECT_TRUE(x == y) << shape << " " << f << " differs";
    }
  }
  // Other options: another store id (the files' bytes 16..23).
  gen::GenerateOptions c = Options("sphere", 128, t / "c");
  c.band = 2;
  ASSERT_TRUE(gen::Generate(c).ok());
  EXPECT_NE(Slurp(c.output + "/index.vxi").substr(16, 8),
            Slurp(t / "sphere1/index.vxi").substr(16, 8));
}

// The pyramid built with the bricks is, byte for byte, the one BuildLod (as
// `vox-ingest --add-lod` runs it) writes of the finished store: every shape,
// bricks of 2^5 and of 2^2 voxels (the generator's occupancy then tests the
// neighbours of most voxels).
TEST(GenStore, ThePyramidBuiltWithTheBricksIsBuildLods) {
  TempDir t;
  int n = 0;
  for (const char* shape : {"sphere", "bumpy", "rough"})
    for (const char* levels : {"auto", "5+2"}) {
      SCOPED_TRACE(std::string(shape) + " " + levels);
      gen::GenerateOptions o = Options(shape, 128, t / ("s" + std::to_string(n++)));
      o.levels = levels;
      ASSERT_TRUE(gen::Generate(o).ok());
      auto files = [&] {
        std::map<std::string, std::string> bytes;
        for (const auto& e : fs::recursive_directory_iterator(o.output + "/lod"))
          if (e.is_regular_file())
            bytes[fs::relative(e.path(), o.output).string()] = Slurp(e.path());
        return bytes;
      };
      const auto streamed = files();
      ASSERT_EQ(streamed.size(), 2u * 5u);  // levels 1..5 of a 2^7 grid
      LodBuildOptions lo;
      lo.force = true;
      ASSERT_TRUE(BuildLod(o.output, lo).ok());
      const auto built = files();
      for (const auto& [name, bytes] : built) EXPECT_TRUE(streamed.at(name) == bytes) << name;
    }
}

TEST(GenStore, BadOptionsAreRefusedBeforeWriting) {
  TempDir t;
  auto expect_error = [&](gen::GenerateOptions o, const std::string& needle) {
    auto st = gen::Generate(o);
    ASSERT_FALSE(st.ok()) << needle;
    EXPECT_EQ(st.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(st.status().message().find(needle), std::string::npos) << st.status().message();
    EXPECT_TRUE(t.Entries().empty());
  };
  expect_error(Options("sphere", 100, t / "x"), "--size 100");
  expect_error(Options("sphere", uint64_t(1) << 21, t / "x"), "--size 2097152");
  expect_error(Options("sphere", 1, t / "x"), "--size 1");
  expect_error(Options("cube", 64, t / "x"), "unknown shape 'cube'");
  auto o = Options("sphere", 64, t / "x");
  o.levels = "3+4";
  expect_error(o, "--levels 3+4");
  o.levels = "0+6";
  expect_error(o, "--levels 0+6");
  o.levels = "2+x";
  expect_error(o, "--levels 2+x");
  o = Options("sphere", 1 << 12, t / "x");
  o.levels = "1+11";
  expect_error(o, "--levels 1+11");
  o = Options("sphere", 64, t / "x");
  o.band = 0;
  expect_error(o, "--band 0");
  o.band = std::nan("");
  expect_error(o, "--band nan");
  o = Options("sphere", 64, t / "x");
  o.normal_bits = 7;
  expect_error(o, "--normal-bits 7");
}

TEST(GenStore, MissingParentDirectoryLeavesNothing) {
  TempDir t;
  auto st = gen::Generate(Options("sphere", 32, t / "no/such/dir"));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.status().message().find("no/such"), std::string::npos) << st.status().message();
  EXPECT_TRUE(t.Entries().empty());
}

TEST(GenStore, CancelledGenerationLeavesNoStore) {
  TempDir t;
  std::atomic<bool> cancel{true};
  gen::GenerateOptions o = Options("sphere", 256, t / "c");
  o.cancel = &cancel;
  auto st = gen::Generate(o);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.status().message().find("interrupted"), std::string::npos);
  EXPECT_TRUE(t.Entries().empty());
}

// Interrupted once every brick is written, while the index and the pyramid
// are (the cancel flag polled by the pyramid's finish): the whole store is
// abandoned, the message says so (not only "no pyramid"), and the store
// --force was to replace is as it was.
TEST(GenStore, CancelledWhileFinishingKeepsTheEarlierStoreAndSaysSo) {
  TempDir t;
  const std::string s = t / "s";
  ASSERT_TRUE(gen::Generate(Options("sphere", 32, s)).ok());
  const std::string index = Slurp(s + "/index.vxi");
  std::atomic<bool> cancel{false};
  gen::GenerateOptions o = Options("fog", 128, s);
  o.force = true;
  o.cancel = &cancel;
  uint64_t last_done = 0, total = 0;
  auto st = gen::Generate(o, [&](const gen::GenerateProgressReport& r) {
    EXPECT_GE(r.done, last_done);
    last_done = r.done;
    total = r.total;
    if (r.done == r.total) cancel.store(true);
  });
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(total, uint64_t(64));  // 2^(3 * brick level): bricks of 32^3
  EXPECT_EQ(last_done, total);
  EXPECT_EQ(st.status().message(), "interrupted; no store written: '" + s + "' is as it was before");
  EXPECT_EQ(Slurp(s + "/index.vxi"), index);
  EXPECT_EQ(t.Entries(), std::set<std::string>{"s"});
  // Without an earlier store: nothing at all.
  cancel.store(false);
  o.output = t / "new";
  o.force = false;
  st = gen::Generate(o, [&](const gen::GenerateProgressReport& r) {
    if (r.done == r.total) cancel.store(true);
  });
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.status().message(),
            "interrupted; no store written at '" + o.output + "', nothing left behind");
  EXPECT_EQ(t.Entries(), std::set<std::string>{"s"});
}

// ------------------------------------------------------------ the program

struct Result {
  int exit_code = -1;
  std::string err;
};

Result RunGen(const std::string& args) {
  TempDir t;
  std::string cmd = std::string(VOX_GEN_BIN) + " " + args + " 2> " + (t / "err.txt");
  int status = std::system(cmd.c_str());
  Result r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = Slurp(t / "err.txt");
  return r;
}

TEST(GenTool, WritesAStoreAndRefusesBadArgumentsNamingTheFlag) {
  TempDir t;
  const std::string s = t / "s";
  Result ok = RunGen("sphere " + s + " --size 32 --quiet");
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(ok.err.empty()) << ok.err;
  const std::string index = Slurp(s + "/index.vxi");
  ASSERT_FALSE(index.empty());

  struct Bad {
    std::string args, needle;
    int code;
  };
  for (const Bad& b :
       {Bad{"sphere " + t / "a" + " --size 48", "--size 48: must be a power of two", 2},
        Bad{"sphere " + t / "a" + " --size 2097152", "--size 2097152", 2},
        Bad{"sphere " + t / "a" + " --size big", "--size big: not a whole number", 2},
        Bad{"sphere " + t / "a", "--size is required", 2},
        Bad{"blob " + t / "a" + " --size 32", "unknown shape 'blob'", 2},
        Bad{"sphere " + t / "a" + " --size 32 --levels 4+4", "--levels 4+4", 2},
        Bad{"sphere " + t / "a" + " --size 32 --band -1", "--band -1", 2},
        Bad{"sphere " + t / "a" + " --size 32 --frobnicate", "unknown option --frobnicate", 2},
        Bad{"sphere " + s + " --size 64 --quiet", "already exists (use --force", 1}}) {
    Result r = RunGen(b.args);
    EXPECT_EQ(r.exit_code, b.code) << b.args << ": " << r.err;
    EXPECT_NE(r.err.find(b.needle), std::string::npos) << b.args << ": " << r.err;
  }
  // Nothing was written: only the first store, unchanged.
  EXPECT_EQ(t.Entries(), std::set<std::string>{"s"});
  EXPECT_TRUE(Slurp(s + "/index.vxi") == index);
  // --force replaces it.
  Result forced = RunGen("bumpy " + s + " --size 64 --force --quiet");
  ASSERT_EQ(forced.exit_code, 0) << forced.err;
  auto store = Store::Open(s, OpenOptions());
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->meta().grid_name, "bumpy");
  EXPECT_EQ(t.Entries(), std::set<std::string>{"s"});
}

TEST(GenTool, InterruptedRunLeavesNoStore) {
  TempDir t;
  const std::string s = t / "big";
  for (int sig : {SIGINT, SIGKILL}) {
    pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      execl(VOX_GEN_BIN, VOX_GEN_BIN, "sphere", s.c_str(), "--size", "16384", "--threads", "1",
            "--quiet", (char*)nullptr);
      _exit(127);
    }
    // Kill it once it has written bricks: its temporary directory holds a
    // non-empty bricks.vxb (so its signal handling is set up). An event, not
    // a delay: no load makes it come too early or too late; if the
    // generator ends first, the test fails.
    int status = 0;
    bool exited = false, writing = false;
    while (!writing && !exited) {
      for (const std::string& e : t.Entries()) {
        std::error_code ec;
        if (e.find(".tmp-") != std::string::npos && fs::file_size(t / e + "/bricks.vxb", ec) > 0 && !ec)
          writing = true;
      }
      exited = waitpid(pid, &status, WNOHANG) == pid;
      if (!writing && !exited) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ASSERT_FALSE(exited) << "vox-gen ended before it was interrupted, status " << status;
    kill(pid, sig);
    waitpid(pid, &status, 0);
    EXPECT_FALSE(fs::exists(s));
    EXPECT_FALSE(Store::Open(s, OpenOptions()).ok());
    if (sig == SIGINT) {
      // Caught: the generator stops and removes its temporary directory.
      EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1);
      EXPECT_TRUE(t.Entries().empty());
    } else {
      // Killed: only a temporary directory without an index, which never opens.
      for (const std::string& e : t.Entries()) {
        EXPECT_NE(e.find(".tmp-"), std::string::npos) << e;
        EXPECT_FALSE(fs::exists(t / e + "/index.vxi"));
        EXPECT_FALSE(Store::Open(t / e, OpenOptions()).ok());
      }
    }
  }
}

}  // namespace
}  // namespace vox

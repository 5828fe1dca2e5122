// vox-ingest as a program: exit codes and messages for good and bad input.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <vector>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "storage/store.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

struct Result {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

Result RunTool(const std::string& args) {
  Result r;
  std::string cmd = std::string(VOX_INGEST_BINARY) + " " + args + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  int status = ::pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

class IngestToolTest : public ::testing::Test {
 protected:
  void SetUp() override {
    openvdb::initialize();
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        8.0f, openvdb::Vec3f(-20.0f, 0.0f, 5.0f), 1.0f, 3.0f);
    grid->setName("sphere");
    auto vec = openvdb::Vec3fGrid::create();
    vec->setName("vel");
    vec->tree().setValueOn(openvdb::Coord(0), openvdb::Vec3f(1.0f));
    vdb_ = dir_.File("in.vdb");
    testutil::WriteVdb(vdb_, {grid, vec});
  }
  testutil::TempDir dir_;
  std::string vdb_;
};

TEST_F(IngestToolTest, IngestsAndRefusesToOverwrite) {
  std::string out = dir_.File("store");
  Result r = RunTool(vdb_ + " " + out + " --levels 3+4 --zstd-level 5 --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("occupied voxels"), std::string::npos) << r.output;
  auto store = Store::Open(out, OpenOptions{});
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  EXPECT_EQ((*store)->meta().brick_level, 3);
  EXPECT_EQ((*store)->meta().levels, 7);
  EXPECT_NE((*store)->meta().build_options.find("--levels 3+4"), std::string::npos);
  r = RunTool(vdb_ + " " + out + " --quiet");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--force"), std::string::npos) << r.output;
  r = RunTool(vdb_ + " " + out + " --quiet --force");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output, "") << "--quiet prints nothing";
}

TEST_F(IngestToolTest, UsageErrors) {
  std::string out = dir_.File("x");
  for (const std::string& args :
       {std::string(""), vdb_, vdb_ + " " + out + " extra", vdb_ + " " + out + " --levels",
        vdb_ + " " + out + " --levels 30+30", vdb_ + " " + out + " --threads two",
        vdb_ + " " + out + " --isovalue nan", vdb_ + " " + out + " --zstd-level 99",
        vdb_ + " " + out + " --bogus"}) {
    Result r = RunTool(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    // One line naming the problem and a pointer to the help, never the help.
    EXPECT_EQ(r.output.rfind("vox-ingest: ", 0), 0u) << r.output;
    EXPECT_EQ(r.output.substr(r.output.find('\n') + 1), "see vox-ingest --help\n") << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST_F(IngestToolTest, BadMemoryBudgetsNameTheFlagAndLeaveNoStore) {
  std::string out = dir_.File("m");
  for (const std::string& v :
       std::initializer_list<std::string>{"", "abc", "0", "-5", "12Q", "0.5"}) {
    Result r = RunTool(vdb_ + " " + out + " --quiet --memory-mb" + (v.empty() ? "" : " " + v));
    EXPECT_EQ(r.exit_code, 2) << v << "\n" << r.output;
    EXPECT_NE(r.output.find("--memory-mb"), std::string::npos) << r.output;
  }
  // Parsed, but below what an ingest needs: the ingest refuses it.
  Result r = RunTool(vdb_ + " " + out + " --quiet --memory-mb 8");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--memory-mb"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(out));
  r = RunTool(vdb_ + " " + out + " --quiet --memory-mb 256");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(out));
}

// --normal-bits 12 against the default 16 on a level set large enough that
// attributes, not headers, make up the bricks file: the same voxels, normals
// within the two precisions' documented errors of each other (storage/FORMAT.md:
// 0.06 and 0.004 degrees from the exact normal), a smaller bricks file.
TEST_F(IngestToolTest, NormalBits12KeepsVoxelsAndShrinksBricks) {
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      40.0f, openvdb::Vec3f(3.5f, -7.25f, 11.0f), 1.0f, 3.0f);
  grid->setName("ball");
  std::string vdb = dir_.File("ball.vdb");
  testutil::WriteVdb(vdb, {grid});
  const std::string dir16 = dir_.File("s16"), dir12 = dir_.File("s12");
  Result r = RunTool(vdb + " " + dir16 + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunTool(vdb + " " + dir12 + " --quiet --normal-bits 12");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto s16 = Store::Open(dir16, OpenOptions{});
  auto s12 = Store::Open(dir12, OpenOptions{});
  ASSERT_TRUE(s16.ok()) << s16.status().ToString();
  ASSERT_TRUE(s12.ok()) << s12.status().ToString();
  EXPECT_NE((*s12)->meta().build_options.find("--normal-bits 12"), std::string::npos)
      << (*s12)->meta().build_options;
  EXPECT_EQ((*s12)->meta().origin, (*s16)->meta().origin);
  EXPECT_EQ((*s12)->meta().levels, (*s16)->meta().levels);
  EXPECT_EQ((*s12)->meta().voxel_count, (*s16)->meta().voxel_count);

  auto v16 = testutil::ReadAll(**s16);
  auto v12 = testutil::ReadAll(**s12);
  ASSERT_TRUE(v16.ok()) << v16.status().ToString();
  ASSERT_TRUE(v12.ok()) << v12.status().ToString();
  ASSERT_GT(v16->size(), 50000u);
  ASSERT_EQ(v12->size(), v16->size());
  const double bound_degrees = 0.06 + 0.004;
  double max_degrees = 0;
  auto it12 = v12->begin();
  for (const auto& [g, sv16] : *v16) {
    const auto& [g12, sv12] = *it12++;
    ASSERT_EQ(g12, g) << "occupied voxels differ";
    auto a16 = (*s16)->Attributes(sv16.brick, sv16.payload);
    auto a12 = (*s12)->Attributes(sv12.brick, sv12.payload);
    ASSERT_TRUE(a16.ok()) << a16.status().ToString();
    ASSERT_TRUE(a12.ok()) << a12.status().ToString();
    // The angle from atan2(|a x b|, a . b): acos loses small angles near 1.
    const glm::dvec3 n16(a16->normal), n12(a12->normal);
    const double degrees =
        std::atan2(glm::length(glm::cross(n16, n12)), glm::dot(n16, n12)) * 180.0 / M_PI;
    max_degrees = std::max(max_degrees, degrees);
    ASSERT_LE(degrees, bound_degrees) << "normal at grid " << g[0] << "," << g[1] << "," << g[2];
  }
  EXPECT_GT(max_degrees, 0.0) << "12 bits changed no normal";

  const auto size16 = std::filesystem::file_size(dir16 + "/bricks.vxb");
  const auto size12 = std::filesystem::file_size(dir12 + "/bricks.vxb");
  EXPECT_LT(size12, size16);
  std::printf(
      "%zu voxels: bricks.vxb %ju bytes at 12 bits, %ju at 16 (ratio %.3f); normals at "
      "most %.4f degrees apart\n",
      v16->size(), uintmax_t(size12), uintmax_t(size16), double(size12) / double(size16),
      max_degrees);
}

TEST_F(IngestToolTest, NormalBitsOutside8To16Refused) {
  Result help = RunTool("--help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.output.find("--normal-bits B"), std::string::npos) << help.output;
  const std::string out = dir_.File("nb");
  for (const std::string& bits :
       std::initializer_list<std::string>{"7", "17", "99", "0", "-12", "abc", "12.5", "''"}) {
    Result r = RunTool(vdb_ + " " + out + " --normal-bits " + bits);
    EXPECT_EQ(r.exit_code, 2) << bits << "\n" << r.output;
    const std::string first_line = r.output.substr(0, r.output.find('\n'));
    EXPECT_NE(first_line.find("--normal-bits"), std::string::npos) << bits << "\n" << r.output;
    // An empty value is refused as empty; the others with the range.
    EXPECT_NE(first_line.find(bits == "''" ? "an empty value" : "8..16"), std::string::npos)
        << bits << "\n" << r.output;
  }
  Result r = RunTool(vdb_ + " " + out + " --normal-bits");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--normal-bits needs a value"), std::string::npos) << r.output;
  // Nothing was written: no store, no temporary directory beside it.
  std::vector<std::string> left;
  for (const auto& e : std::filesystem::directory_iterator(dir_.path()))
    left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"in.vdb"});
}

TEST_F(IngestToolTest, BadInputs) {
  std::string text = dir_.File("notes.txt");
  std::ofstream(text) << "hello\n";
  std::string cut = dir_.File("cut.vdb");
  {
    std::ifstream in(vdb_, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(cut, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() / 2));
  }
  struct Case {
    std::string args, words;
  } cases[] = {
      {text + " " + dir_.File("o1"), "not a readable OpenVDB file"},
      {cut + " " + dir_.File("o2"), "truncated"},
      {dir_.File("missing.vdb") + " " + dir_.File("o3"), "no such file"},
      {vdb_ + " " + dir_.File("o4") + " --grid nope", "no grid named 'nope'"},
      {vdb_ + " " + dir_.File("o5") + " --grid vel", "vec3s"},
      {vdb_ + " " + dir_.File("o6") + " --color sphere", "colour grid 'sphere'"},
      {vdb_ + " " + vdb_ + "/store", vdb_},
  };
  for (const Case& c : cases) {
    Result r = RunTool(c.args + " --quiet");
    EXPECT_EQ(r.exit_code, 1) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << c.args << "\n" << r.output;
  }
  for (const char* o : {"o1", "o2", "o3", "o4", "o5", "o6"})
    EXPECT_FALSE(std::filesystem::exists(dir_.File(o))) << o;
}

}  // namespace
}  // namespace vox

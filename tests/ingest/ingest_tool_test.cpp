// vox-ingest as a program: exit codes and messages for good and bad input.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

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
    EXPECT_NE(r.output.find("usage: vox-ingest"), std::string::npos) << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(out));
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

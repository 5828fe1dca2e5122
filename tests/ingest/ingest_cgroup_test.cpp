// vox-ingest in a memory cgroup far smaller than what OpenVDB's tree of the
// input would take: a generated level-set sphere (about 550k leaves; its
// delayed-load tree alone held some 200 MiB) ingests with default flags in a
// 96 MiB cgroup, and the store matches an unlimited ingest's (the same
// metadata, bricks and voxels). Needs root and a writable memory cgroup;
// skips otherwise.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "storage/store.h"
#include "tests/common/cgroup_util.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using vox::testing::CgroupRunOptions;
using vox::testing::RunInMemoryCgroup;

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(IngestCgroupTest, MidSizeSphereInASmallCgroup) {
  VOX_REQUIRE_MEMORY_CGROUP();
  openvdb::initialize();
  testutil::TempDir dir;
  const std::string vdb = dir.File("sphere.vdb");
  {
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        1200.0f, openvdb::Vec3f(0.0f), 1.0f, 3.0f);
    g->setName("sphere");
    testutil::WriteVdb(vdb, {g});
  }
  auto run = [&](const std::string& name, uint64_t limit) {
    CgroupRunOptions o;
    o.limit_bytes = limit;
    o.stderr_path = dir.File(name + ".log");
    return RunInMemoryCgroup({VOX_INGEST_BINARY, vdb, dir.File(name + ".store"), "--threads", "2"},
                             o);
  };
  auto free_run = run("unlimited", 0);
  ASSERT_TRUE(free_run.ok()) << free_run.status().ToString();
  ASSERT_EQ(free_run->exit_code, 0) << free_run->Describe() << ReadAll(dir.File("unlimited.log"));
  const uint64_t limit = uint64_t(96) << 20;
  auto small = run("small", limit);
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  std::printf("unlimited: %s; in %llu MiB: %s\n", free_run->Describe().c_str(),
              (unsigned long long)(limit >> 20), small->Describe().c_str());
  ASSERT_EQ(small->exit_code, 0) << small->Describe() << ReadAll(dir.File("small.log"));
  auto a = Store::Open(dir.File("unlimited.store"), OpenOptions{});
  auto b = Store::Open(dir.File("small.store"), OpenOptions{});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ((*a)->meta().bbox_min, (*b)->meta().bbox_min);
  EXPECT_EQ((*a)->meta().bbox_max, (*b)->meta().bbox_max);
  EXPECT_EQ((*a)->meta().levels, (*b)->meta().levels);
  // The summary lines: occupied voxels and bricks.
  auto summary = [&](const std::string& log) {
    const std::string s = ReadAll(log);
    const size_t at = s.find("occupied voxels in");
    return at == std::string::npos ? s : s.substr(s.rfind("wrote", at), s.find("(levels", at) -
                                                                             s.rfind("wrote", at));
  };
  std::string sa = summary(dir.File("unlimited.log")), sb = summary(dir.File("small.log"));
  sa = sa.substr(sa.find(':'));
  sb = sb.substr(sb.find(':'));
  EXPECT_EQ(sa, sb);
}

}  // namespace
}  // namespace vox

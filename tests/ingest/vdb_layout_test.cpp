// The .vdb layout check (ingest/internal/vdb_layout.h) on files OpenVDB
// writes: whole files pass (and OpenVDB reads them), every truncation fails
// with an error naming the file, and a cut inside a grid names that grid.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include "ingest/internal/vdb_layout.h"
#include "tests/ingest/ingest_test_util.h"

namespace vox {
namespace {

using ingest_internal::CheckVdbLayout;

class VdbLayoutTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }

  std::string Write(const std::string& name, const std::string& bytes) {
    std::string path = dir_.File(name);
    std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    return path;
  }
  static std::string Read(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  // Two small grids, the second named "last" (its data ends the file).
  std::string TwoGridFile() {
    auto a = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(4.0f, openvdb::Vec3f(0.0f),
                                                                      1.0f, 2.0f);
    a->setName("first");
    a->insertMeta("note", openvdb::StringMetadata("file metadata follows the header"));
    auto b = openvdb::FloatGrid::create(0.0f);
    b->setName("last");
    b->tree().setValue(openvdb::Coord(100, 0, -3), 2.5f);
    openvdb::GridPtrVec grids{a, b};
    std::string path = dir_.File("two.vdb");
    openvdb::io::File f(path);
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("vdb_layout_test"));
    f.write(grids, meta);
    f.close();
    return path;
  }

  testutil::TempDir dir_;
};

TEST_F(VdbLayoutTest, WholeFilesPassAndOpenVdbReadsThem) {
  const std::string path = TwoGridFile();
  ASSERT_TRUE(CheckVdbLayout(path).ok()) << CheckVdbLayout(path).ToString();
  openvdb::io::File f(path);
  f.open();
  EXPECT_EQ(f.readAllGridMetadata()->size(), 2u);
}

TEST_F(VdbLayoutTest, EveryTruncationIsRefusedNamingTheFile) {
  const std::string bytes = Read(TwoGridFile());
  ASSERT_GT(bytes.size(), 100u);
  for (size_t keep = 0; keep < bytes.size(); keep += (keep < 400 ? 1 : 37)) {
    SCOPED_TRACE("kept " + std::to_string(keep) + " of " + std::to_string(bytes.size()));
    const std::string path = Write("cut.vdb", bytes.substr(0, keep));
    Status s = CheckVdbLayout(path);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
    EXPECT_NE(s.message().find(path), std::string::npos) << s.ToString();
  }
  // A cut inside the last grid's data names that grid and the byte range.
  Status s = CheckVdbLayout(Write("tail.vdb", bytes.substr(0, bytes.size() - 1)));
  EXPECT_NE(s.message().find("grid 'last' spans bytes"), std::string::npos) << s.ToString();
}

TEST_F(VdbLayoutTest, NotAVdbFile) {
  Status s = CheckVdbLayout(Write("text.vdb", "definitely not a vdb file"));
  EXPECT_EQ(s.code(), StatusCode::kCorruption);
  EXPECT_NE(s.message().find("no VDB magic number"), std::string::npos) << s.ToString();
  Status missing = CheckVdbLayout(dir_.File("missing.vdb"));
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("missing.vdb"), std::string::npos);
}

TEST_F(VdbLayoutTest, StreamsWithoutOffsetsAreLeftToOpenVdb) {
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setName("streamed");
  g->tree().setValue(openvdb::Coord(1, 2, 3), 1.0f);
  std::ostringstream os(std::ios::binary);
  openvdb::io::Stream(os).write(openvdb::GridPtrVec{g});
  const std::string path = Write("stream.vdb", os.str());
  EXPECT_TRUE(CheckVdbLayout(path).ok()) << CheckVdbLayout(path).ToString();
}

}  // namespace
}  // namespace vox

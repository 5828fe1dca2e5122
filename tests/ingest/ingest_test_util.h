// Helpers for the ingest tests: a temporary directory, writing VDB files, and
// FakeStore, a StoreWriter that records what the ingest hands it (checking
// the StoreWriter contract as it goes) and can fail on demand.
// The fake writer's AddBrick is thread-safe, like StoreWriter's; the rest is
// used by one test thread.
#ifndef VOX_TESTS_INGEST_INGEST_TEST_UTIL_H_
#define VOX_TESTS_INGEST_INGEST_TEST_UTIL_H_

#include <stdlib.h>

#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include "ingest/ingest.h"
#include "storage/store.h"

namespace vox::testutil {

using Ijk = std::array<int64_t, 3>;

class TempDir {
 public:
  TempDir() {
    const char* base = std::getenv("TMPDIR");
    std::string tmpl = std::string(base && *base ? base : "/tmp") + "/vox-ingest-test-XXXXXX";
    char* p = ::mkdtemp(tmpl.data());
    EXPECT_NE(p, nullptr);
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

inline void WriteVdb(const std::string& path, const openvdb::GridPtrVec& grids) {
  openvdb::io::File(path).write(grids);
}

struct FakeStore {
  // Inputs: failures to inject.
  int fail_add_at = -1;  // AddBrick number (0-based) that fails with "disk full"
  bool fail_create = false;
  bool fail_finish = false;
  // What the ingest did.
  bool created = false, finished = false, force = false;
  StoreMeta meta;
  WriteOptions options;
  std::map<Ijk, std::vector<BrickVoxel>> bricks;  // by brick coordinate

  // Voxels in VDB index coordinates with their attributes.
  std::map<Ijk, VoxelAttributes> Voxels() const {
    std::map<Ijk, VoxelAttributes> out;
    const int b = meta.levels - meta.brick_level;
    for (const auto& [bc, voxels] : bricks)
      for (const BrickVoxel& v : voxels) {
        Ijk ijk{meta.origin.x + (bc[0] << b) + v.x, meta.origin.y + (bc[1] << b) + v.y,
                meta.origin.z + (bc[2] << b) + v.z};
        out[ijk] = v.attr;
      }
    return out;
  }

  WriterFactory Factory() {
    return [this](const std::string& dir, const StoreMeta& m,
                  const WriteOptions& o) -> StatusOr<std::unique_ptr<StoreWriter>> {
      if (fail_create) return IoError(dir + ": cannot create (injected)");
      created = true;
      meta = m;
      options = o;
      force = o.force;
      return std::unique_ptr<StoreWriter>(new Writer(this));
    };
  }

 private:
  class Writer : public StoreWriter {
   public:
    explicit Writer(FakeStore* s) : s_(s) {}
    Status AddBrick(const glm::u64vec3& c, std::vector<BrickVoxel> voxels) override {
      std::lock_guard<std::mutex> lock(mu_);  // AddBrick is called concurrently
      EXPECT_FALSE(s_->finished);
      if (adds_++ == s_->fail_add_at) return IoError("/fake/bricks: No space left on device");
      const int b = s_->meta.levels - s_->meta.brick_level;
      const uint64_t top = uint64_t(1) << s_->meta.brick_level, size = uint64_t(1) << b;
      EXPECT_LT(c.x, top);
      EXPECT_LT(c.y, top);
      EXPECT_LT(c.z, top);
      EXPECT_FALSE(voxels.empty()) << "empty brick";
      Ijk key{int64_t(c.x), int64_t(c.y), int64_t(c.z)};
      EXPECT_EQ(s_->bricks.count(key), 0u) << "brick added twice";
      std::set<Ijk> seen;
      for (const BrickVoxel& v : voxels) {
        EXPECT_LT(v.x, size);
        EXPECT_LT(v.y, size);
        EXPECT_LT(v.z, size);
        EXPECT_TRUE(seen.insert(Ijk{v.x, v.y, v.z}).second) << "duplicate voxel in a brick";
      }
      s_->bricks[key] = std::move(voxels);
      return OkStatus();
    }
    Status Finish() override {
      if (s_->fail_finish) return IoError("/fake: fsync failed (injected)");
      s_->finished = true;
      return OkStatus();
    }

   private:
    FakeStore* s_;
    std::mutex mu_;
    int adds_ = 0;
  };
};

}  // namespace vox::testutil

#endif  // VOX_TESTS_INGEST_INGEST_TEST_UTIL_H_

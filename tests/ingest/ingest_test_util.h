// Helpers for the ingest tests: a temporary directory, writing VDB files,
// reading every voxel of a store back, and FakeStore, a StoreWriter that
// records what the ingest hands it (checking the StoreWriter contract as it
// goes) and can fail on demand.
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

#include "core/octree.h"
#include "core/util/status.h"
#include "ingest/ingest.h"
#include "storage/store.h"
#include "storage/store_writer.h"

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

// Where a store keeps a voxel's attributes.
struct StoredVoxel {
  uint32_t brick = kNoBrick, payload = 0;
};

// Walks the octree under `cell` of `pool` (grid coordinates `base`, 2^size_log2 voxels
// per axis), adding its occupied voxels to `out`.
inline Status WalkCells(Store& store, const CompactCell* pool, uint32_t cell, int size_log2, Ijk base,
                        uint32_t brick, std::map<Ijk, StoredVoxel>* out) {
  const OctreeView v = store.view();
  const int child_log2 = size_log2 - 1;
  for (unsigned digit = 0; digit < 8; ++digit) {
    ChildRef ref = ChildOf(pool[cell], digit, v.levels - size_log2, v);
    if (ref.kind == ChildRef::kEmpty) continue;
    Ijk c{base[0] + (int64_t(digit & 1) << child_log2),
          base[1] + (int64_t((digit >> 1) & 1) << child_log2),
          base[2] + (int64_t((digit >> 2) & 1) << child_log2)};
    if (ref.kind == ChildRef::kPayload) {
      if (!out->emplace(c, StoredVoxel{brick, ref.index}).second)
        return InternalError("voxel listed twice");
    } else if (ref.kind == ChildRef::kBrick) {
      if (brick != kNoBrick) return CorruptionError("a brick refers to a brick");
      uint32_t id = ref.index;
      VOX_ASSIGN_OR_RETURN(BrickView b, store.FetchBrick(id));
      VOX_RETURN_IF_ERROR(WalkCells(store, b.cells, 0, child_log2, c, id, out));
    } else {
      VOX_RETURN_IF_ERROR(WalkCells(store, pool, ref.index, child_log2, c, brick, out));
    }
  }
  return OkStatus();
}

// Every occupied voxel of a store (grid coordinates), found by walking its octree
// (every brick fetched).
inline StatusOr<std::map<Ijk, StoredVoxel>> ReadAll(Store& store) {
  std::map<Ijk, StoredVoxel> grid_voxels;
  OctreeView v = store.view();
  VOX_RETURN_IF_ERROR(WalkCells(store, v.top, 0, v.levels, Ijk{0, 0, 0}, kNoBrick, &grid_voxels));
  return grid_voxels;
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
  std::vector<Ijk> add_order;                      // brick coordinates as added

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
      s_->add_order.push_back(key);
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

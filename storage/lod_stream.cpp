// LodStream: the pyramid of a store built from the bricks its producer
// hands to the StoreWriter.
#include <algorithm>
#include <chrono>
#include <filesystem>

#include <glm/gtc/packing.hpp>

#include "core/util/file.h"
#include "storage/internal/brick_codec.h"
#include "storage/internal/format.h"
#include "storage/internal/lod_reduce.h"
#include "storage/internal/lod_write.h"
#include "storage/lod.h"

namespace vox {

namespace fs = std::filesystem;
namespace si = storage_internal;

// LodStream: the producer's bricks reduced as BuildLod's JobReducer reduces
// them from the store (VoxelSums), into a PyramidWriter inside the store's
// temporary directory.
class LodStream::Impl {
 public:
  Impl(const StoreMeta& base, const WriteOptions& base_options, const LodBuildOptions& options)
      : meta_(base),
        store_id_(base_options.store_id),
        normal_bits_(base_options.normal_bits),
        options_(options),
        format_(base),
        flags_(si::AttrFlags(base)),
        depth_(base.levels - base.brick_level) {}

  ~Impl() {
    pyramid_.reset();  // its writers' temporaries first
    std::error_code ec;
    if (!temp_.empty() && !published_) fs::remove_all(temp_, ec);
  }

  Status Init(const std::string& store_temp_dir) {
    if (store_id_ == 0)
      return InvalidArgumentError("a pyramid built with its store needs the store's id");
    if (meta_.lod_level != 0)
      return InvalidArgumentError("a level-of-detail store has no pyramid of its own");
    target_ = (fs::path(store_temp_dir) / si::kLodDirName).string();
    VOX_ASSIGN_OR_RETURN(temp_, CreateTemporary(target_, /*directory=*/true));
    pyramid_ = std::make_unique<si::PyramidWriter>();
    return pyramid_->Init(meta_, store_id_, temp_, options_);
  }

  StatusOr<std::shared_ptr<LodReducedBrick>> Reduce(const glm::u64vec3& brick,
                                                    const std::vector<BrickVoxel>& voxels,
                                                    const Occupied& occupied) const {
    if (voxels.empty()) return InvalidArgumentError("a base brick without voxels");
    const uint64_t side = uint64_t(1) << depth_;
    // The voxels in Morton order, as the store keeps them (they usually
    // come so; brick-local coordinates fit MortonKey21's 21 bits).
    thread_local std::vector<LeafPoint> points;
    thread_local std::vector<uint32_t> order;
    bool sorted = depth_ <= 21;
    uint64_t prev = 0;
    for (size_t i = 0; i < voxels.size(); ++i) {
      const BrickVoxel& v = voxels[i];
      if (v.x >= side || v.y >= side || v.z >= side)
        return InvalidArgumentError("a voxel outside its brick");
      if (!sorted) continue;
      const uint64_t key = MortonKey21(v.x, v.y, v.z);
      sorted = i == 0 || key > prev;
      prev = key;
    }
    order.resize(voxels.size());
    points.clear();
    if (sorted) {
      for (size_t i = 0; i < order.size(); ++i) order[i] = uint32_t(i);
    } else {
      points.resize(voxels.size());
      for (size_t i = 0; i < voxels.size(); ++i)
        points[i] = {voxels[i].x, voxels[i].y, voxels[i].z, NodeRef(i)};
      SortMorton(&points);
      for (size_t i = 0; i < order.size(); ++i) order[i] = uint32_t(points[i].ref);
    }
    // Occupancy inside the brick: a bitmap while it is small, else a search.
    thread_local std::vector<uint64_t> bitmap;
    const bool use_bitmap = depth_ <= si::kLodMaxBitmapDepth;
    auto bit_of = [&](const glm::u64vec3& l) {
      return size_t((l.z << (2 * depth_)) | (l.y << depth_) | l.x);
    };
    if (use_bitmap) {
      bitmap.assign(std::max<size_t>(1, (size_t(1) << (3 * depth_)) / 64), 0);
      for (const BrickVoxel& v : voxels) {
        const size_t b = bit_of(glm::u64vec3(v.x, v.y, v.z));
        bitmap[b >> 6] |= uint64_t(1) << (b & 63);
      }
    } else if (sorted) {  // the points, for the search
      points.resize(voxels.size());
      for (size_t i = 0; i < voxels.size(); ++i)
        points[i] = {voxels[i].x, voxels[i].y, voxels[i].z, NodeRef(i)};
    }
    const int64_t n = int64_t(1) << meta_.levels;
    auto occupied_at = [&](const glm::i64vec3& g) -> bool {
      if (g.x < 0 || g.y < 0 || g.z < 0 || g.x >= n || g.y >= n || g.z >= n) return false;
      const glm::u64vec3 c(g);
      if ((c >> uint64_t(depth_)) != brick) return occupied(c);
      const glm::u64vec3 l = c - (brick << uint64_t(depth_));
      if (use_bitmap) {
        const size_t b = bit_of(l);
        return ((bitmap[b >> 6] >> (b & 63)) & 1) != 0;
      }
      return std::binary_search(points.begin(), points.end(), LeafPoint{l.x, l.y, l.z},
                                MortonLess);
    };

    auto r = std::make_shared<LodReducedBrick>();
    r->brick = brick;
    si::Cascade cascade(pyramid_->local());
    cascade.Reserve(voxels.size());
    const glm::u64vec3 corner = brick << uint64_t(depth_);
    for (const uint32_t i : order) {
      const BrickVoxel& v = voxels[i];
      const glm::u64vec3 coord = corner + glm::u64vec3(v.x, v.y, v.z);
      cascade.Push(1, coord, si::VoxelSums(Stored(v.attr), coord, format_, occupied_at));
    }
    cascade.TakeInto(r.get());
    return r;
  }

  Status Take(LodReducedBrick& r) {
    if (options_.cancel != nullptr && options_.cancel->load())
      return IoError("interrupted; no level-of-detail pyramid written");
    const LeafPoint at{r.brick.x, r.brick.y, r.brick.z};
    if (taken_ > 0 && !MortonLess(last_, at))
      return InvalidArgumentError("the pyramid's base bricks came out of brick order");
    last_ = at;
    ++taken_;
    return pyramid_->Take(r);
  }

  StatusOr<LodBuildStats> Finish(const std::string& store_temp_dir) {
    const auto t0 = std::chrono::steady_clock::now();
    if (options_.cancel != nullptr && options_.cancel->load())
      return IoError("interrupted; no level-of-detail pyramid written");
    if ((fs::path(store_temp_dir) / si::kLodDirName).string() != target_)
      return InvalidArgumentError("the pyramid was begun in another directory");
    // The store it was built with: this one, bricks and all.
    OpenOptions oo;
    oo.unfinished_ingest = true;
    VOX_ASSIGN_OR_RETURN(auto base, Store::Open(store_temp_dir, oo));
    StoreMeta expected = meta_;
    const StoreMeta& got = base->meta();
    expected.voxel_count = got.voxel_count;
    expected.brick_count = got.brick_count;
    expected.top_cells = got.top_cells;
    expected.bbox_min = got.bbox_min;
    expected.bbox_max = got.bbox_max;
    const uint64_t bricks = depth_ == 0 ? got.voxel_count : got.brick_count;
    if (base->store_id() != store_id_ || bricks != taken_ ||
        si::EncodeMeta(expected) != si::EncodeMeta(got))
      return InternalError("the level-of-detail pyramid built with store '" + store_temp_dir +
                           "' does not match it");
    base.reset();
    LodBuildStats stats;
    VOX_RETURN_IF_ERROR(pyramid_->Finish(&stats));
    pyramid_.reset();
    stats.base_bricks_read = taken_;
    VOX_RETURN_IF_ERROR(SyncDir(temp_));
    VOX_RETURN_IF_ERROR(PublishAtomically(temp_, target_, "level-of-detail pyramid", {}));
    published_ = true;
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return stats;
  }

 private:
  // The attributes the store gives back for `a` (FORMAT.md: quantised
  // normals, half colours; fields it lacks at their defaults).
  VoxelAttributes Stored(const VoxelAttributes& a) const {
    VoxelAttributes s;
    if (flags_ & si::kAttrNormal)
      s.normal = si::DecodeOctNormal(
          si::EncodeOctNormal(a.normal, normal_bits_));
    if (flags_ & si::kAttrDensity) s.density = a.density;
    if (flags_ & si::kAttrTemperature) s.temperature = a.temperature;
    if (flags_ & si::kAttrColor)
      for (int k = 0; k < 3; ++k) s.color[k] = glm::unpackHalf1x16(glm::packHalf1x16(a.color[k]));
    return s;
  }

  const StoreMeta meta_;
  const uint64_t store_id_;
  const int normal_bits_;
  const LodBuildOptions options_;
  const si::BaseFormat format_;
  const uint8_t flags_;
  const int depth_;
  std::string target_, temp_;  // STORE_TEMP/lod, and the pyramid's temporary beside it
  bool published_ = false;
  std::unique_ptr<si::PyramidWriter> pyramid_;
  uint64_t taken_ = 0;
  LeafPoint last_;  // the last brick taken
};

StatusOr<std::unique_ptr<LodStream>> LodStream::Create(const std::string& store_temp_dir,
                                                       const StoreMeta& base,
                                                       const WriteOptions& base_options,
                                                       const LodBuildOptions& options) {
  auto impl = std::make_unique<Impl>(base, base_options, options);
  VOX_RETURN_IF_ERROR(impl->Init(store_temp_dir));
  return std::unique_ptr<LodStream>(new LodStream(std::move(impl)));
}

LodStream::LodStream(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
LodStream::~LodStream() = default;

StatusOr<std::shared_ptr<LodReducedBrick>> LodStream::Reduce(
    const glm::u64vec3& brick, const std::vector<BrickVoxel>& voxels,
    const Occupied& occupied) const {
  return impl_->Reduce(brick, voxels, occupied);
}

Status LodStream::Take(const std::shared_ptr<LodReducedBrick>& brick) {
  if (brick == nullptr) return InvalidArgumentError("no reduced brick");
  return impl_->Take(*brick);
}

StatusOr<LodBuildStats> LodStream::Finish(const std::string& store_temp_dir) {
  return impl_->Finish(store_temp_dir);
}

}  // namespace vox

// The bricks of one grid's ingest (grid_ingest_impl.h): the brick map
// (brick key, leaf or tile) in Morton order, each brick's voxels built from
// the leaves and tiles it overlaps, and the pipeline that streams them
// through the writer and the level-of-detail pyramid.
#include "ingest/internal/grid_ingest_impl.h"

#include <algorithm>
#include <mutex>

#include "core/util/parallel.h"

namespace vox::ingest_internal {

template <class ValueT>
bool GridIngest<ValueT>::InOccupiedTile(const Coord& c) const {
  for (const int log2 : tile_log2_) {
    const int mask = ~((1 << log2) - 1);
    if (tile_set_.count({c.x() & mask, c.y() & mask, c.z() & mask, log2})) return true;
  }
  return false;
}

template <class ValueT>
Status GridIngest<ValueT>::BuildBrickMap(const CoordBBox& occ) {
  // Brick coordinate range of a box, clipped to the occupied bbox.
  auto range = [&](const CoordBBox& box, int64_t lo[3], int64_t hi[3]) {
    for (int a = 0; a < 3; ++a) {
      int64_t mn = std::max<int64_t>(box.min()[a], occ.min()[a]);
      int64_t mx = std::min<int64_t>(box.max()[a], occ.max()[a]);
      if (mn > mx) return false;
      lo[a] = (mn - origin_[a]) >> B_;
      hi[a] = (mx - origin_[a]) >> B_;
    }
    return true;
  };
  int64_t lo[3], hi[3];
  // Bricks the occupied tiles cover: refuse counts a store cannot index.
  long double tile_bricks = 0;
  for (const Tile& t : tiles_)
    if (range(t.box, lo, hi))
      tile_bricks += (long double)(hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
  if (tile_bricks > (long double)(uint64_t(1) << 26))
    return ResourceExhaustedError(
        cx_.options.input + ": grid " + Quote(cx_.meta.grid_name) +
        " has occupied active tiles covering " + std::to_string(double(tile_bricks)) +
        " bricks of " + std::to_string(int64_t(1) << B_) + "^3 voxels; vox expands tiles to "
        "voxels and cannot index that many");
  // (brick key, leaf index) and (brick key, tile index) pairs, in key
  // (Morton) order.
  for (uint32_t i : leaves_) {
    if (!range(NodeBox(i), lo, hi)) continue;
    for (int64_t z = lo[2]; z <= hi[2]; ++z)
      for (int64_t y = lo[1]; y <= hi[1]; ++y)
        for (int64_t x = lo[0]; x <= hi[0]; ++x) leaf_map_.push_back({Key(x, y, z), i});
  }
  std::vector<uint32_t>().swap(leaves_);
  for (uint32_t i = 0; i < tiles_.size(); ++i) {
    if (!range(tiles_[i].box, lo, hi)) continue;
    for (int64_t z = lo[2]; z <= hi[2]; ++z)
      for (int64_t y = lo[1]; y <= hi[1]; ++y)
        for (int64_t x = lo[0]; x <= hi[0]; ++x) tile_map_.push_back({Key(x, y, z), i});
  }
  std::sort(leaf_map_.begin(), leaf_map_.end());
  std::sort(tile_map_.begin(), tile_map_.end());
  // Count the bricks.
  size_t li = 0, ti = 0;
  while (li < leaf_map_.size() || ti < tile_map_.size()) {
    NextBrick(&li, &ti);
    ++brick_count_;
  }
  return OkStatus();
}

// The brick at map positions *li, *ti (the smaller key of the two), whose
// entries it consumes.
template <class ValueT>
auto GridIngest<ValueT>::NextBrick(size_t* li, size_t* ti) const -> BrickWork {
  BrickWork bw;
  const uint64_t kNone = ~uint64_t(0);
  const uint64_t lk = *li < leaf_map_.size() ? leaf_map_[*li].first : kNone;
  const uint64_t tk = *ti < tile_map_.size() ? tile_map_[*ti].first : kNone;
  bw.key = std::min(lk, tk);
  for (; *li < leaf_map_.size() && leaf_map_[*li].first == bw.key; ++*li)
    bw.leaves.push_back(leaf_map_[*li].second);
  for (; *ti < tile_map_.size() && tile_map_[*ti].first == bw.key; ++*ti)
    bw.tiles.push_back(tile_map_[*ti].second);
  return bw;
}

// One brick's voxels in Morton order and, with the pyramid, its share of
// it in *reduced. Runs concurrently on many bricks; decodes the leaves it
// needs from the file, then drops them.
template <class ValueT>
StatusOr<std::vector<BrickVoxel>> GridIngest<ValueT>::ExtractBrick(
    const BrickWork& bw, std::shared_ptr<LodReducedBrick>* reduced) {
  int64_t rmin[3];
  for (int a = 0; a < 3; ++a) rmin[a] = origin_[a] + (KeyCoord(bw.key, a) << B_);
  std::unique_ptr<ColorReader> color = cx_.color ? cx_.color->NewReader() : nullptr;
  Builder builder(*topo_, level_set_, color.get(), rmin);
  std::unique_ptr<ColorReader> temperature =
      cx_.temperature ? cx_.temperature->NewReader() : nullptr;
  builder.SetTemperature(temperature.get());
  std::vector<BrickVoxel> out = BrickVoxels(bw, rmin, builder);
  if (lod_ == nullptr || out.empty()) return out;
  // The store's voxels beside the brick, from the leaves the builder has
  // decoded (a level set's normals read the same face neighbours) and
  // the occupied tiles.
  auto& source = builder.source();
  Status read_error;
  auto occupied = [&](const glm::u64vec3& g) {
    const Coord c(int(origin_[0] + int64_t(g.x)), int(origin_[1] + int64_t(g.y)),
                  int(origin_[2] + int64_t(g.z)));
    try {
      uint32_t leaf;
      ValueT v;
      if (!source.Probe(c, &leaf, &v)) return Occupied(v) && InOccupiedTile(c);
      const openvdb::Index n = openvdb::Index(((c.x() & 7) << 6) | ((c.y() & 7) << 3) |
                                              (c.z() & 7));
      return source.Mask(leaf).isOn(n) && Occupied(source.Values(leaf)[n]);
    } catch (const openvdb::Exception& e) {
      if (read_error.ok())
        read_error = CorruptionError(cx_.options.input + ": grid " + Quote(cx_.meta.grid_name) +
                                     ": cannot read voxel data: " + e.what());
      return false;
    }
  };
  const glm::u64vec3 brick(KeyCoord(bw.key, 0), KeyCoord(bw.key, 1), KeyCoord(bw.key, 2));
  auto r = lod_->Reduce(brick, out, occupied);
  VOX_RETURN_IF_ERROR(read_error);
  VOX_ASSIGN_OR_RETURN(*reduced, std::move(r));
  return out;
}

// The voxels of the brick whose lowest index coordinate is rmin, in Morton order.
template <class ValueT>
std::vector<BrickVoxel> GridIngest<ValueT>::BrickVoxels(const BrickWork& bw,
                                                        const int64_t rmin[3],
                                                        Builder& builder) {
  const int64_t size = int64_t(1) << B_;
  int64_t rmax[3];
  for (int a = 0; a < 3; ++a) rmax[a] = rmin[a] + size - 1;
  std::vector<BrickVoxel> out;
  auto& source = builder.source();

  // Fast path: bricks of at least 8^3 without tiles hold whole leaves
  // (the origin is aligned to the brick size); visiting the leaves in
  // Morton order and each leaf's voxels in Morton order gives the voxels
  // in the writer's order without a sort.
  const bool morton_walk = B_ >= 3 && bw.tiles.empty();
  if (morton_walk) {
    std::vector<LeafPoint> order(bw.leaves.size());  // leaf coordinates in the brick
    uint64_t expected = 0;
    for (size_t i = 0; i < bw.leaves.size(); ++i) {
      const auto& leaf = topo_->leaves()[bw.leaves[i]];
      order[i] = {uint64_t(leaf.origin[0] - rmin[0]) >> 3,
                  uint64_t(leaf.origin[1] - rmin[1]) >> 3,
                  uint64_t(leaf.origin[2] - rmin[2]) >> 3, NodeRef(i)};
      expected += leaf.active;
    }
    SortMorton(&order);
    out.reserve(size_t(expected));
    const auto& table = MortonLeafOrder();
    for (const LeafPoint& p : order) {
      const uint32_t leaf = bw.leaves[p.ref];
      builder.BeginLeaf(leaf);
      const auto& mask = source.Mask(leaf);
      for (uint16_t n : table) {
        if (!mask.isOn(n)) continue;
        const ValueT v = builder.LeafValue(n);
        if (Occupied(v)) out.push_back(builder.FromLeaf(n, v));
      }
    }
    return out;
  }
  for (uint32_t leaf : bw.leaves) {
    builder.BeginLeaf(leaf);
    const Coord o = source.Origin(leaf);
    for (auto m = source.Mask(leaf).beginOn(); m; ++m) {
      const openvdb::Index n = m.pos();
      const int64_t x = int64_t(o.x()) + int(n >> 6), y = int64_t(o.y()) + int((n >> 3) & 7),
                    z = int64_t(o.z()) + int(n & 7);
      if (x < rmin[0] || x > rmax[0] || y < rmin[1] || y > rmax[1] || z < rmin[2] ||
          z > rmax[2])
        continue;
      const ValueT v = builder.LeafValue(n);
      if (Occupied(v)) out.push_back(builder.FromLeaf(n, v));
    }
  }
  for (uint32_t ti : bw.tiles) {
    const Tile& t = tiles_[ti];
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max<int64_t>(t.box.min()[a], rmin[a]);
      hi[a] = std::min<int64_t>(t.box.max()[a], rmax[a]);
    }
    for (int64_t x = lo[0]; x <= hi[0]; ++x)
      for (int64_t y = lo[1]; y <= hi[1]; ++y)
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
          out.push_back(builder.FromTile(Coord{int(x), int(y), int(z)}, t.value));
  }
  // Morton order (octal digit x | y << 1 | z << 2), which the writer
  // builds its cells in, so its sort finds them sorted.
  std::vector<LeafPoint> order(out.size());
  for (size_t i = 0; i < out.size(); ++i) order[i] = {out[i].x, out[i].y, out[i].z, NodeRef(i)};
  SortMorton(&order);
  std::vector<BrickVoxel> sorted(out.size());
  for (size_t k = 0; k < order.size(); ++k) sorted[k] = out[order[k].ref];
  return sorted;
}

// Leaf offsets (x << 6 | y << 3 | z) of an 8^3 leaf in Morton order.
template <class ValueT>
const std::array<uint16_t, 512>& GridIngest<ValueT>::MortonLeafOrder() {
  static const std::array<uint16_t, 512> table = [] {
    std::array<uint16_t, 512> t{};
    for (unsigned m = 0; m < 512; ++m) {
      unsigned x = 0, y = 0, z = 0;
      for (int b = 0; b < 3; ++b) {
        x |= ((m >> (3 * b)) & 1) << b;
        y |= ((m >> (3 * b + 1)) & 1) << b;
        z |= ((m >> (3 * b + 2)) & 1) << b;
      }
      t[m] = uint16_t(x << 6 | y << 3 | z);
    }
    return t;
  }();
  return table;
}

// Bricks go through a pipeline: the parallel stage builds a brick's voxels
// and hands them to the writer (AddBrick is thread-safe: it encodes and
// compresses in the calling thread); the serial in-order stage reports
// progress.
template <class ValueT>
Status GridIngest<ValueT>::WriteBricks(StoreWriter* writer) {
  struct Item {
    size_t index = 0;
    size_t voxels = 0;
    std::shared_ptr<BrickWork> work;
    std::shared_ptr<LodReducedBrick> lod;  // its share of the pyramid
  };
  const size_t total = brick_count_;
  Message("writing " + std::to_string(total) + " bricks of " + std::to_string(1 << B_) +
          "^3 voxels");
  std::atomic<bool> failed{false};
  std::mutex error_mu;
  Status first_error;
  auto fail = [&](Status s) {
    std::lock_guard<std::mutex> lock(error_mu);
    if (first_error.ok()) first_error = std::move(s);
    failed.store(true);
  };
  size_t next = 0, written = 0, li = 0, ti = 0;
  uint64_t voxels_done = 0;
  const size_t tokens = BricksInFlight();
  RunPipeline<Item>(
      DefaultThreads(), tokens,
      [&](Item& it) {
        if (next >= total || failed.load()) return false;
        it.index = next++;
        it.work = std::make_shared<BrickWork>(NextBrick(&li, &ti));
        return true;
      },
      [&](Item& it) {
        if (failed.load()) return;
        const BrickWork& bw = *it.work;
        uint32_t kept = 0;
        if (writer->Resumed(
                glm::u64vec3(KeyCoord(bw.key, 0), KeyCoord(bw.key, 1), KeyCoord(bw.key, 2)),
                &kept)) {
          it.voxels = kept;  // written by an earlier run (resumable writing)
          it.work.reset();
          return;
        }
        try {
          StatusOr<std::vector<BrickVoxel>> extracted = ExtractBrick(bw, &it.lod);
          if (!extracted.ok()) return fail(extracted.status());
          std::vector<BrickVoxel> voxels = std::move(extracted).value();
          it.voxels = voxels.size();
          if (!voxels.empty()) {
            Status s = writer->AddBrick(
                glm::u64vec3(KeyCoord(bw.key, 0), KeyCoord(bw.key, 1), KeyCoord(bw.key, 2)),
                std::move(voxels));
            if (!s.ok()) fail(s);
          }
        } catch (const openvdb::Exception& e) {
          fail(CorruptionError(cx_.options.input + ": grid " + Quote(cx_.meta.grid_name) +
                               ": cannot read voxel data: " + e.what()));
        } catch (const std::bad_alloc&) {
          fail(ResourceExhaustedError("out of memory while building brick " +
                                      std::to_string(it.index) + " of " + cx_.options.input));
        } catch (const std::exception& e) {
          fail(InternalError(cx_.options.input + ": " + e.what()));
        }
        it.work.reset();
      },
      [&](Item& it) {
        if (failed.load()) return;
        if (it.lod) {  // in brick order
          Status s = lod_->Take(it.lod);
          it.lod.reset();
          if (!s.ok()) return fail(s);
        }
        voxels_done += it.voxels;
        if (it.voxels) ++written;
        if (cx_.progress) cx_.progress->Progress(it.index + 1, total, voxels_done);
        if (cx_.progress && cx_.progress->Cancelled())
          fail(UnavailableError(cx_.options.input + ": ingest cancelled"));
      });
  if (!first_error.ok()) return first_error;
  cx_.stats->occupied_voxels = voxels_done;
  cx_.stats->bricks = written;
  return OkStatus();
}

// Bricks in flight: 2 per thread, fewer when the memory budget left after
// the tables cannot hold them. A brick's worst case: its voxels twice
// (built, then sorted or encoded), its decoded leaves and their face
// neighbours, and the writer's encode and compress buffers.
template <class ValueT>
size_t GridIngest<ValueT>::BricksInFlight() const {
  const int threads = DefaultThreads();
  size_t tokens = size_t(std::max(2, 2 * threads));
  if (cx_.memory_budget == 0) return tokens;
  const uint64_t side = uint64_t(1) << B_;
  const uint64_t voxels = side * side * side;
  const uint64_t leaves = std::max<uint64_t>(1, voxels / 512) * 2 + 8;
  const uint64_t per_brick = voxels * (2 * sizeof(BrickVoxel) + 16) +
                             leaves * (sizeof(ValueT) * 512 + 128);
  const uint64_t fixed = cx_.stats->topology_bytes +
                         (leaf_map_.capacity() + tile_map_.capacity()) * 16 + kProcessBase;
  const uint64_t left = cx_.memory_budget > fixed ? cx_.memory_budget - fixed : 0;
  tokens = std::min<size_t>(tokens, size_t(left / per_brick));
  return std::max<size_t>(tokens, 1);
}

// The members Run (grid_ingest.cpp) calls, for both value types; the rest
// are instantiated through them.
template Status GridIngest<float>::BuildBrickMap(const openvdb::CoordBBox& occ);
template Status GridIngest<double>::BuildBrickMap(const openvdb::CoordBBox& occ);
template Status GridIngest<float>::WriteBricks(StoreWriter* writer);
template Status GridIngest<double>::WriteBricks(StoreWriter* writer);

}  // namespace vox::ingest_internal

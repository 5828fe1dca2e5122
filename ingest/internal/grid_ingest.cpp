// Brick extraction: the ingest of one float or double grid. See grid_ingest.h.
//
// How it streams. The grid's topology is read by CompactTopology
// (vdb_topology.h): one pass over the file keeps a 24-byte record per leaf
// (origin, active count, file offset) and the internal nodes' child masks and
// tile values; no OpenVDB tree is built. Then:
//  1. Exact occupied bbox: scan the leaves from each of the 6 sides in order
//     of their node box until no further leaf can move the bound; each
//     scanned leaf is decoded and dropped. Usually a few hundred leaves; all
//     of them when nothing is occupied.
//  2. Placement (origin, levels), the StoreWriter, and the brick map: one
//     (brick key, leaf or tile) pair per overlap, sorted by brick in z, y, x
//     order (16 bytes per leaf).
//  3. Bricks go through a TBB pipeline: a serial stage gathers a brick's
//     leaves and tiles from the sorted map; a parallel stage decodes them
//     (and, for the gradient, the face neighbours it touches) from the file,
//     builds its voxels (voxel_builder.h) in Morton order and hands them to
//     the writer (which compresses in the calling thread); a serial in-order
//     stage keeps the books and takes each brick's share of the
//     level-of-detail pyramid (LodStream: reduced in the parallel stage,
//     with the neighbours' occupancy from the decoded leaves and the
//     occupied tiles), so the pyramid needs no second pass over the written
//     store. Bricks in flight are bounded by the memory
//     budget (at most 2 per thread). Leaves on a brick's faces are decoded by
//     both bricks (a few % of CPU).
#include "core/util/stopwatch.h"
#include "ingest/internal/grid_ingest.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <set>
#include <unordered_map>
#include <vector>

#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include "core/octree.h"
#include "ingest/internal/vdb_topology.h"
#include "ingest/internal/voxel_builder.h"
#include "storage/lod.h"

namespace vox::ingest_internal {
namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

template <class ValueT>
class GridIngest {
 public:
  using Topology = CompactTopology<ValueT>;
  using Builder = BasicVoxelBuilder<TopologySource<ValueT>>;

  GridIngest(const VdbLayout& layout, const VdbLayout::Grid& grid, Context& cx)
      : layout_(layout), grid_(grid), cx_(cx) {}

  Status Run() {
    const bool level_set = cx_.meta.grid_class == GridClass::kLevelSet;
    level_set_ = level_set;
    iso_ = ValueT(cx_.meta.isovalue);
    threshold_ = ValueT(cx_.meta.threshold);

    // 1. Topology.
    Stopwatch t0;
    {
      auto topology = Topology::Read(cx_.options.input, layout_, grid_);
      if (!topology.ok()) return topology.status();
      topo_ = std::move(topology).value();
    }
    const uint64_t leaf_count = topo_->leaves().size();
    for (uint32_t i = 0; i < leaf_count; ++i)
      if (topo_->leaves()[i].active) leaves_.push_back(i);  // leaves with active voxels
    for (const auto& t : topo_->active_tiles()) {
      ++cx_.stats->active_tiles;
      if (!Occupied(t.value)) continue;
      tiles_.push_back({t.box, t.value});
      cx_.stats->occupied_tile_voxels += t.box.volume();
      const int log2 = std::countr_zero(uint32_t(t.box.dim().x()));
      tile_set_.insert({t.box.min().x(), t.box.min().y(), t.box.min().z(), log2});
      if (std::find(tile_log2_.begin(), tile_log2_.end(), log2) == tile_log2_.end())
        tile_log2_.push_back(log2);
    }
    if (cx_.stats->occupied_tile_voxels > cx_.max_tile_voxels)
      return ResourceExhaustedError(
          cx_.options.input + ": grid " + Quote(cx_.meta.grid_name) +
          " has occupied active tiles that expand to " +
          std::to_string(cx_.stats->occupied_tile_voxels) + " voxels, more than the limit of " +
          std::to_string(cx_.max_tile_voxels) +
          " (--max-voxels; raise it to ingest this grid, which takes time and space in "
          "proportion)");
    cx_.stats->leaf_nodes = leaf_count;
    cx_.stats->active_voxels = topo_->active_voxels();
    cx_.stats->topology_bytes = topo_->MemoryBytes() + leaves_.capacity() * 4;
    cx_.stats->seconds_open += t0.Seconds();
    if (cx_.memory_budget && cx_.stats->topology_bytes > cx_.memory_budget / 2)
      return ResourceExhaustedError(
          cx_.options.input + ": grid " + Quote(cx_.meta.grid_name) + " has " +
          std::to_string(leaf_count) + " leaves whose tables take " +
          std::to_string(cx_.stats->topology_bytes >> 20) + " MiB, more than half the memory "
          "budget of " + std::to_string(cx_.memory_budget >> 20) + " MiB (--memory-mb)");
    Message("grid " + Quote(cx_.meta.grid_name) + ": " + std::to_string(leaf_count) +
            " leaf nodes, " + std::to_string(cx_.stats->active_tiles) + " active tiles, " +
            std::to_string(cx_.stats->active_voxels) + " active voxels");

    // 2. Exact occupied bbox.
    t0.Restart();
    CoordBBox occ = OccupiedBBox();
    cx_.stats->seconds_bbox = t0.Seconds();

    // 3. Placement and writer.
    int64_t bmin[3], bmax[3];
    const bool empty = occ.empty();
    for (int a = 0; a < 3; ++a) {
      bmin[a] = empty ? 0 : occ.min()[a];
      bmax[a] = empty ? -1 : occ.max()[a];
    }
    VOX_ASSIGN_OR_RETURN(Placement pl, PlaceGrid(bmin, bmax, cx_.choice));
    StoreMeta& meta = cx_.meta;
    meta.levels = pl.levels;
    meta.brick_level = pl.brick_level;
    meta.origin = glm::i64vec3(pl.origin[0], pl.origin[1], pl.origin[2]);
    meta.bbox_min = glm::i64vec3(bmin[0], bmin[1], bmin[2]);
    meta.bbox_max = glm::i64vec3(bmax[0], bmax[1], bmax[2]);
    cx_.stats->meta = meta;
    B_ = pl.levels - pl.brick_level;
    for (int a = 0; a < 3; ++a) origin_[a] = pl.origin[a];
    if (empty) {
      Message("nothing occupied: writing an empty store");
    } else {
      Message("occupied bbox [" + std::to_string(bmin[0]) + "," + std::to_string(bmin[1]) + "," +
              std::to_string(bmin[2]) + "] -> [" + std::to_string(bmax[0]) + "," +
              std::to_string(bmax[1]) + "," + std::to_string(bmax[2]) + "], levels " +
              std::to_string(pl.brick_level) + "+" + std::to_string(B_) + " (" +
              std::to_string(cx_.stats->bbox_leaves_read) + " leaves read for the bbox)");
    }
    WriteOptions wo;
    wo.zstd_level = cx_.options.zstd_level;
    wo.normal_bits = cx_.options.normal_bits;
    wo.force = cx_.options.force;
    if (cx_.options.lod) {
      // The level-of-detail pyramid, built with the bricks (LodStream; or,
      // for a writer without a temporary directory, from the finished base
      // store) inside the store's temporary directory: published with it,
      // or not at all. Its coarse stores name the base store's id, chosen here.
      wo.store_id = NewStoreId();
      wo.before_publish = [this](const std::string& temp_dir) -> Status {
        Stopwatch lod_time;
        // A cancel (Ctrl-C in Python, whose ingest child polls it here) stops
        // the pyramid at its next brick, and one that comes as it ends still
        // stops the publication: no store, the old one kept.
        if (lod_ == nullptr) Message("building the level-of-detail pyramid");
        lod_cancel_ = cx_.progress && cx_.progress->Cancelled();
        StatusOr<LodBuildStats> built =
            lod_ ? lod_->Finish(temp_dir) : BuildLod(temp_dir, LodOptions());
        if (lod_cancel_ || (cx_.progress && cx_.progress->Cancelled()))
          return UnavailableError(cx_.options.input + ": ingest cancelled");
        VOX_ASSIGN_OR_RETURN(LodBuildStats ls, std::move(built));
        cx_.stats->lod_levels = ls.levels;
        cx_.stats->seconds_lod = lod_time.Seconds();
        return OkStatus();
      };
    }
    auto writer_or = cx_.factory(cx_.options.output, meta, wo);
    if (!writer_or.ok()) return writer_or.status();
    std::unique_ptr<StoreWriter> writer = std::move(writer_or).value();
    if (cx_.options.lod && !writer->temp_dir().empty()) {
      Message("building the level-of-detail pyramid with the bricks");
      VOX_ASSIGN_OR_RETURN(lod_, LodStream::Create(writer->temp_dir(), meta, wo, LodOptions()));
    }

    // 4. Bricks.
    t0.Restart();
    if (!empty) {
      VOX_RETURN_IF_ERROR(BuildBrickMap(occ));
      VOX_RETURN_IF_ERROR(WriteBricks(writer.get()));
    }
    cx_.stats->seconds_bricks = t0.Seconds();
    t0.Restart();
    if (cx_.progress && cx_.progress->Cancelled())
      return UnavailableError(cx_.options.input + ": ingest cancelled");
    VOX_RETURN_IF_ERROR(writer->Finish());
    cx_.stats->seconds_finish = t0.Seconds();
    return OkStatus();
  }

 private:
  struct Tile {
    CoordBBox box;
    ValueT value;
  };
  struct BrickWork {
    uint64_t key = 0;
    std::vector<uint32_t> leaves;
    std::vector<uint32_t> tiles;
  };

  bool Occupied(ValueT v) const { return level_set_ ? !(v > iso_) : v > threshold_; }

  LodBuildOptions LodOptions() {
    LodBuildOptions lo;
    lo.zstd_level = cx_.options.zstd_level;
    lo.normal_bits = cx_.options.normal_bits;
    lo.threads = cx_.options.threads;
    lo.cancel = &lod_cancel_;
    lo.progress = [this](uint64_t, uint64_t) {
      if (cx_.progress && cx_.progress->Cancelled()) lod_cancel_ = true;
    };
    return lo;
  }

  // A random store id (never 0, which asks the writer for one).
  static uint64_t NewStoreId() {
    std::random_device rd;
    const uint64_t id = (uint64_t(rd()) << 32) ^ rd() ^
                        uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
    return id != 0 ? id : 1;
  }

  // Whether index voxel c lies in an occupied active tile.
  bool InOccupiedTile(const Coord& c) const {
    for (const int log2 : tile_log2_) {
      const int mask = ~((1 << log2) - 1);
      if (tile_set_.count({c.x() & mask, c.y() & mask, c.z() & mask, log2})) return true;
    }
    return false;
  }

  void Message(const std::string& m) {
    if (cx_.progress) cx_.progress->Message(m);
  }

  // The node box of leaf i: bounds its active voxels.
  CoordBBox NodeBox(uint32_t i) const {
    return CoordBBox::createCube(topo_->leaves()[i].Origin(), 8);
  }

  // The occupied voxels' box of leaf i, decoded once.
  const CoordBBox& DecodeOccupied(uint32_t i) {
    auto [it, inserted] = occupied_.try_emplace(i);
    if (!inserted) return it->second;
    std::unique_ptr<ValueT[]> d(new ValueT[512]);
    typename Topology::Mask mask;
    topo_->ReadLeaf(i, d.get(), &mask, &scratch_);
    const Coord o = topo_->leaves()[i].Origin();
    for (auto m = mask.beginOn(); m; ++m) {
      openvdb::Index n = m.pos();
      if (!Occupied(d[n])) continue;
      it->second.expand(o + Coord(int(n >> 6), int((n >> 3) & 7), int(n & 7)));
    }
    ++cx_.stats->bbox_leaves_read;
    return it->second;
  }

  CoordBBox OccupiedBBox() {
    CoordBBox tiles_box;
    for (const Tile& t : tiles_) tiles_box.expand(t.box);
    int64_t lo[3], hi[3];
    const int64_t kBig = std::numeric_limits<int64_t>::max();
    std::vector<uint32_t> order(leaves_.size());
    for (int a = 0; a < 3; ++a) {
      lo[a] = tiles_box.empty() ? kBig : tiles_box.min()[a];
      hi[a] = tiles_box.empty() ? -kBig : tiles_box.max()[a];
      for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
      // Leaf origins along the axis, low to high (the node box is origin..origin+7).
      auto org = [&](uint32_t x) { return topo_->leaves()[leaves_[x]].origin[a]; };
      std::sort(order.begin(), order.end(),
                [&](uint32_t x, uint32_t y) { return org(x) < org(y); });
      for (uint32_t i : order) {
        if (org(i) >= lo[a]) break;
        const CoordBBox& occ = DecodeOccupied(leaves_[i]);
        if (!occ.empty()) lo[a] = std::min<int64_t>(lo[a], occ.min()[a]);
      }
      for (auto r = order.rbegin(); r != order.rend(); ++r) {
        if (int64_t(org(*r)) + 7 <= hi[a]) break;
        const CoordBBox& occ = DecodeOccupied(leaves_[*r]);
        if (!occ.empty()) hi[a] = std::max<int64_t>(hi[a], occ.max()[a]);
      }
      if (lo[a] == kBig) return CoordBBox();  // nothing occupied anywhere
    }
    return CoordBBox(Coord(int(lo[0]), int(lo[1]), int(lo[2])),
                     Coord(int(hi[0]), int(hi[1]), int(hi[2])));
  }

  // Brick keys are Morton keys of brick coordinates (MortonKey21): bricks are
  // built and appended to the brick file in about that order (the parallel
  // stage reorders only the bricks in flight), so bricks close in space lie
  // close in the file and a reader's window of neighbouring records serves
  // many rays.
  static uint64_t Key(int64_t x, int64_t y, int64_t z) {
    return MortonKey21(uint64_t(x), uint64_t(y), uint64_t(z));
  }
  static int64_t KeyCoord(uint64_t k, int a) {
    uint64_t v = (k >> a) & 0x1249249249249249ull;  // bit 3i -> bit i
    v = (v | v >> 2) & 0x10c30c30c30c30c3ull;
    v = (v | v >> 4) & 0x100f00f00f00f00full;
    v = (v | v >> 8) & 0x1f0000ff0000ffull;
    v = (v | v >> 16) & 0x1f00000000ffffull;
    v = (v | v >> 32) & 0x1fffff;
    return int64_t(v);
  }

  Status BuildBrickMap(const CoordBBox& occ) {
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
  BrickWork NextBrick(size_t* li, size_t* ti) const {
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
  StatusOr<std::vector<BrickVoxel>> ExtractBrick(const BrickWork& bw,
                                                 std::shared_ptr<LodReducedBrick>* reduced) {
    int64_t rmin[3];
    for (int a = 0; a < 3; ++a) rmin[a] = origin_[a] + (KeyCoord(bw.key, a) << B_);
    std::unique_ptr<ColorReader> color = cx_.color ? cx_.color->NewReader() : nullptr;
    Builder builder(*topo_, level_set_, color.get(), rmin);
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
  std::vector<BrickVoxel> BrickVoxels(const BrickWork& bw, const int64_t rmin[3],
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
  static const std::array<uint16_t, 512>& MortonLeafOrder() {
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
  Status WriteBricks(StoreWriter* writer) {
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
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, Item>(
            tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) -> Item {
              if (next >= total || failed.load()) {
                fc.stop();
                return Item{};
              }
              return Item{next++, 0,
                          std::make_shared<BrickWork>(NextBrick(&li, &ti)), nullptr};
            }) &
            tbb::make_filter<Item, Item>(
                tbb::filter_mode::parallel,
                [&](Item it) -> Item {
                  if (failed.load()) return it;
                  const BrickWork& bw = *it.work;
                  try {
                    StatusOr<std::vector<BrickVoxel>> extracted = ExtractBrick(bw, &it.lod);
                    if (!extracted.ok()) {
                      fail(extracted.status());
                      return it;
                    }
                    std::vector<BrickVoxel> voxels = std::move(extracted).value();
                    it.voxels = voxels.size();
                    if (!voxels.empty()) {
                      Status s = writer->AddBrick(
                          glm::u64vec3(KeyCoord(bw.key, 0), KeyCoord(bw.key, 1),
                                       KeyCoord(bw.key, 2)),
                          std::move(voxels));
                      if (!s.ok()) fail(s);
                    }
                  } catch (const openvdb::Exception& e) {
                    fail(CorruptionError(cx_.options.input + ": grid " +
                                         Quote(cx_.meta.grid_name) +
                                         ": cannot read voxel data: " + e.what()));
                  } catch (const std::bad_alloc&) {
                    fail(ResourceExhaustedError("out of memory while building brick " +
                                                std::to_string(it.index) + " of " +
                                                cx_.options.input));
                  } catch (const std::exception& e) {
                    fail(InternalError(cx_.options.input + ": " + e.what()));
                  }
                  it.work.reset();
                  return it;
                }) &
            tbb::make_filter<Item, void>(
                tbb::filter_mode::serial_in_order, [&](Item it) {
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
                }));
    if (!first_error.ok()) return first_error;
    cx_.stats->occupied_voxels = voxels_done;
    cx_.stats->bricks = written;
    return OkStatus();
  }

  // Bricks in flight: 2 per thread, fewer when the memory budget left after
  // the tables cannot hold them. A brick's worst case: its voxels twice
  // (built, then sorted or encoded), its decoded leaves and their face
  // neighbours, and the writer's encode and compress buffers.
  size_t BricksInFlight() const {
    const int threads = tbb::this_task_arena::max_concurrency();
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
  // Code, libraries, OpenVDB's registries, thread stacks, allocator arenas.
  static constexpr uint64_t kProcessBase = uint64_t(64) << 20;

  const VdbLayout& layout_;
  const VdbLayout::Grid& grid_;
  Context& cx_;
  std::unique_ptr<Topology> topo_;
  bool level_set_ = true;
  ValueT iso_{}, threshold_{};
  std::vector<uint32_t> leaves_;  // leaves with active voxels (until the brick map)
  std::unordered_map<uint32_t, CoordBBox> occupied_;  // leaves decoded for the bbox
  std::vector<char> scratch_;
  std::vector<Tile> tiles_;       // occupied active tiles
  int B_ = 0;
  int64_t origin_[3] = {0, 0, 0};
  std::vector<std::pair<uint64_t, uint32_t>> leaf_map_, tile_map_;  // (brick key, index)
  size_t brick_count_ = 0;
  std::set<std::array<int, 4>> tile_set_;  // occupied tiles: origin, log2 of their side
  std::vector<int> tile_log2_;             // the sides they have
  std::atomic<bool> lod_cancel_{false};
  std::unique_ptr<LodStream> lod_;  // the pyramid built with the bricks
};
}  // namespace

Status IngestGrid(const VdbLayout& layout, const VdbLayout::Grid& grid, bool double_values,
                  Context& cx) {
  if (double_values) return GridIngest<double>(layout, grid, cx).Run();
  return GridIngest<float>(layout, grid, cx).Run();
}

}  // namespace vox::ingest_internal

// GridIngest, the ingest of one float or double grid (grid_ingest.h), shared
// by its two halves: grid_ingest.cpp reads the topology, finds the occupied
// bbox, places the grid and creates the writer; grid_bricks.cpp maps the
// bricks and streams them through the writer. Private to ingest.
#ifndef VOX_INGEST_INTERNAL_GRID_INGEST_IMPL_H_
#define VOX_INGEST_INTERNAL_GRID_INGEST_IMPL_H_

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/octree.h"
#include "ingest/internal/grid_ingest.h"
#include "ingest/internal/vdb_topology.h"
#include "ingest/internal/voxel_builder.h"
#include "storage/lod.h"

namespace vox::ingest_internal {

template <class ValueT>
class GridIngest {
 public:
  using Topology = CompactTopology<ValueT>;
  using Builder = BasicVoxelBuilder<TopologySource<ValueT>>;
  using Coord = openvdb::Coord;
  using CoordBBox = openvdb::CoordBBox;

  GridIngest(const VdbLayout& layout, const VdbLayout::Grid& grid, Context& cx)
      : layout_(layout), grid_(grid), cx_(cx) {}

  Status Run();

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

  // grid_ingest.cpp.
  // 1. The topology, the occupied tiles, and the limits they must keep.
  Status ReadTopology();
  // 2. The exact occupied bbox.
  CoordBBox OccupiedBBox();
  // The occupied voxels' box of leaf i, decoded once.
  const CoordBBox& DecodeOccupied(uint32_t i);
  // 3. The placement of the occupied bbox `occ` into cx_.meta, origin_ and B_.
  Status Place(const CoordBBox& occ);
  // The store's writer (and the pyramid built with its bricks).
  StatusOr<std::unique_ptr<StoreWriter>> CreateWriter();
  LodBuildOptions LodOptions();
  // A random store id (never 0, which asks the writer for one).
  static uint64_t NewStoreId();

  // grid_bricks.cpp: 4. the bricks.
  Status BuildBrickMap(const CoordBBox& occ);
  Status WriteBricks(StoreWriter* writer);
  BrickWork NextBrick(size_t* li, size_t* ti) const;
  // Whether index voxel c lies in an occupied active tile.
  bool InOccupiedTile(const Coord& c) const;
  StatusOr<std::vector<BrickVoxel>> ExtractBrick(const BrickWork& bw,
                                                 std::shared_ptr<LodReducedBrick>* reduced);
  std::vector<BrickVoxel> BrickVoxels(const BrickWork& bw, const int64_t rmin[3],
                                      Builder& builder);
  static const std::array<uint16_t, 512>& MortonLeafOrder();
  size_t BricksInFlight() const;

  bool Occupied(ValueT v) const { return level_set_ ? !(v > iso_) : v > threshold_; }
  void Message(const std::string& m) {
    if (cx_.progress) cx_.progress->Message(m);
  }
  // The node box of leaf i: bounds its active voxels.
  CoordBBox NodeBox(uint32_t i) const {
    return CoordBBox::createCube(topo_->leaves()[i].Origin(), 8);
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

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_GRID_INGEST_IMPL_H_

// Brick extraction: the ingest of one float or double grid. See grid_ingest.h;
// the topology, the bbox (1), the placement and the writer (2) are here, the
// brick map (2) and the bricks (3) in grid_bricks.cpp.
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
#include "ingest/internal/grid_ingest_impl.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <limits>
#include <random>

#include "core/util/stopwatch.h"
#include "ingest/internal/resume_key.h"

namespace vox::ingest_internal {

template <class ValueT>
Status GridIngest<ValueT>::Run() {
  level_set_ = cx_.meta.grid_class == GridClass::kLevelSet;
  iso_ = ValueT(cx_.meta.isovalue);
  threshold_ = ValueT(cx_.meta.threshold);
  VOX_RETURN_IF_ERROR(ReadTopology());

  // 2. Exact occupied bbox.
  Stopwatch t0;
  const CoordBBox occ = OccupiedBBox();
  cx_.stats->seconds_bbox = t0.Seconds();

  // 3. Placement and writer.
  VOX_RETURN_IF_ERROR(Place(occ));
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<StoreWriter> writer, CreateWriter());

  // 4. Bricks.
  t0.Restart();
  if (!occ.empty()) {
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

template <class ValueT>
Status GridIngest<ValueT>::ReadTopology() {
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
  return OkStatus();
}

template <class ValueT>
Status GridIngest<ValueT>::Place(const CoordBBox& occ) {
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
  return OkStatus();
}

template <class ValueT>
StatusOr<std::unique_ptr<StoreWriter>> GridIngest<ValueT>::CreateWriter() {
  const StoreMeta& meta = cx_.meta;
  WriteOptions wo;
  wo.zstd_level = cx_.options.zstd_level;
  wo.normal_bits = cx_.options.normal_bits;
  wo.force = cx_.options.force;
  wo.resume_key = ResumeKeyOf(cx_.options, "");
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
  if (!writer->resume_note().empty()) Message(writer->resume_note());
  // Bricks kept from an earlier run are not built again, so the pyramid is
  // built from the whole base store before it is published (BuildLod: the
  // same pyramid, byte for byte).
  if (cx_.options.lod && !writer->temp_dir().empty() && writer->resumed_bricks() == 0) {
    Message("building the level-of-detail pyramid with the bricks");
    VOX_ASSIGN_OR_RETURN(lod_, LodStream::Create(writer->temp_dir(), meta, wo, LodOptions()));
  }
  return writer;
}

template <class ValueT>
LodBuildOptions GridIngest<ValueT>::LodOptions() {
  LodBuildOptions lo;
  lo.zstd_level = cx_.options.zstd_level;
  lo.normal_bits = cx_.options.normal_bits;
  lo.threads = cx_.options.threads;
  lo.cancel = &lod_cancel_;
  lo.unfinished_ingest = true;
  lo.progress = [this](uint64_t, uint64_t) {
    if (cx_.progress && cx_.progress->Cancelled()) lod_cancel_ = true;
  };
  return lo;
}

template <class ValueT>
uint64_t GridIngest<ValueT>::NewStoreId() {
  std::random_device rd;
  const uint64_t id = (uint64_t(rd()) << 32) ^ rd() ^
                      uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
  return id != 0 ? id : 1;
}

template <class ValueT>
const openvdb::CoordBBox& GridIngest<ValueT>::DecodeOccupied(uint32_t i) {
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

template <class ValueT>
openvdb::CoordBBox GridIngest<ValueT>::OccupiedBBox() {
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

Status IngestGrid(const VdbLayout& layout, const VdbLayout::Grid& grid, bool double_values,
                  Context& cx) {
  if (double_values) return GridIngest<double>(layout, grid, cx).Run();
  return GridIngest<float>(layout, grid, cx).Run();
}

}  // namespace vox::ingest_internal

// vox::Ingest: OpenVDB grid -> vox store. See ingest.h for the contract.
//
// How it streams. The file is opened with OpenVDB's delayed loading: reading
// the grid loads its tree topology (nodes and active masks) but leaves every
// leaf buffer on disk (memory-mapped) until a value is read. Values are only
// ever read through private copies of leaf buffers (LeafValues below), so
// the tree itself stays topology-only for the whole ingest. Then:
//  1. Topology pass: list the leaves with active voxels (and their node box) and
//     the active tiles; no voxel values are read.
//  2. Exact occupied bbox: scan the leaves from each of the 6 sides in order
//     of their node box until no further leaf can move the bound; each
//     scanned leaf is decoded and dropped. Usually a few hundred leaves; all
//     of them when nothing is occupied.
//  3. Placement (origin, levels), the StoreWriter, and the brick map: brick
//     coordinate -> the leaves and tiles that overlap it.
//  4. Bricks go through a TBB pipeline: a parallel stage decodes the brick's
//     leaves (and, for the gradient, the face neighbours it touches), builds
//     its voxels in Morton order and hands them to the writer (which
//     compresses in the calling thread); a serial in-order stage keeps the
//     books. Peak memory: the topology + the bricks in flight (2 per thread).
//     Leaves on a brick's faces are decoded by both bricks (a few % of CPU).
#include "ingest/ingest.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <unordered_map>
#include <vector>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include "core/stopwatch.h"

namespace vox {
namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

void InitOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

std::string Quote(const std::string& s) { return "'" + s + "'"; }

// Smallest n with 2^n >= extent (extent >= 1).
int CeilLog2(uint64_t extent) {
  int n = 0;
  while ((uint64_t(1) << n) < extent) ++n;
  return n;
}

int64_t AlignDown(int64_t v, int b) { return (v >> b) << b; }  // arithmetic shift: floor

// ---------------------------------------------------------------------------
// Leaf values without touching the tree.
//
// With delayed loading, reading a value through the tree loads the leaf's
// buffer into the tree for good. Instead, every leaf is decoded into a
// private copy of its (out-of-core) buffer, used, and dropped, so the tree
// stays topology-only and memory stays bounded. It also sidesteps an
// OpenVDB 10 defect: when LeafBuffer::doLoad throws (corrupt leaf data) it
// leaves the buffer claiming to be out of core while holding an array, and
// destroying or reading that buffer again crashes. A private copy that fails
// to decode is deliberately leaked (a few kB, corrupt files only) and the
// tree's own buffers are never loaded.

template <class LeafT>
class LeafValues {
 public:
  using Buffer = typename LeafT::Buffer;
  using ValueT = typename LeafT::ValueType;

  // The leaf's values (offset x << 6 | y << 3 | z), decoded once per
  // LeafValues; may throw an OpenVDB exception for corrupt data.
  const ValueT* Get(const LeafT* leaf) {
    if (leaf == last_leaf_) return last_data_;
    auto it = index_.find(leaf);
    const ValueT* data;
    if (it != index_.end()) {
      data = it->second;
    } else {
      const Buffer& in_tree = leaf->buffer();
      if (!in_tree.isOutOfCore() && !in_tree.empty()) {
        data = in_tree.data();  // already in memory (delayed loading off)
      } else {
        auto* copy = new Buffer(in_tree);  // shares the file mapping, reads nothing yet
        data = copy->data();  // decodes; if this throws, `copy` is leaked on purpose
        owned_.emplace_back(copy);
      }
      index_.emplace(leaf, data);
    }
    last_leaf_ = leaf;
    last_data_ = data;
    return data;
  }
  void Clear() {
    index_.clear();
    owned_.clear();
    last_leaf_ = nullptr;
  }

 private:
  std::unordered_map<const LeafT*, const ValueT*> index_;
  std::vector<std::unique_ptr<Buffer>> owned_;
  const LeafT* last_leaf_ = nullptr;
  const ValueT* last_data_ = nullptr;
};

// A tree accessor that caches the internal nodes but never a leaf: OpenVDB's
// default accessor keeps a pointer to the cached leaf's values, which loads
// the leaf's buffer into the tree.
template <class TreeT>
using NoLeafAccessor = openvdb::tree::ValueAccessor2<const TreeT, false, 1, 2>;

// Values of a whole tree read through LeafValues: leaves decoded privately,
// tiles and background from the topology.
template <class GridT>
class PrivateReader {
 public:
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;

  explicit PrivateReader(const GridT& grid) : acc_(grid.constTree()) {}

  ValueT Value(const Coord& c) {
    if (const LeafT* leaf = acc_.probeConstLeaf(c)) return leaves_.Get(leaf)[LeafT::coordToOffset(c)];
    return acc_.getValue(c);  // a tile or the background: no leaf buffer involved
  }
  const ValueT* Leaf(const LeafT* leaf) { return leaves_.Get(leaf); }
  void Clear() { leaves_.Clear(); }

 private:
  NoLeafAccessor<TreeT> acc_;
  LeafValues<LeafT> leaves_;
};

// ---------------------------------------------------------------------------
// Colour sampling from a vec3 grid of the same file.

class ColorReader {
 public:
  virtual ~ColorReader() = default;
  // The colour at main-grid index coordinate `ijk`.
  virtual glm::vec3 At(const Coord& ijk) = 0;
};

class ColorSource {
 public:
  virtual ~ColorSource() = default;
  virtual std::unique_ptr<ColorReader> NewReader() = 0;
};

template <class CGridT>
class TypedColorSource : public ColorSource {
 public:
  TypedColorSource(typename CGridT::Ptr grid, const openvdb::math::Transform& main)
      : grid_(std::move(grid)), main_(main), same_(grid_->transform() == main) {}

  std::unique_ptr<ColorReader> NewReader() override {
    return std::make_unique<Reader>(*grid_, main_, same_);
  }

 private:
  class Reader : public ColorReader {
   public:
    Reader(const CGridT& grid, const openvdb::math::Transform& main, bool same)
        : grid_(grid), main_(main), same_(same), values_(grid) {}
    glm::vec3 At(const Coord& ijk) override {
      openvdb::Vec3d v;
      if (same_) {
        v = openvdb::Vec3d(values_.Value(ijk));
      } else {
        // Trilinear, as openvdb::tools::BoxSampler.
        openvdb::Vec3d p = grid_.transform().worldToIndex(main_.indexToWorld(ijk));
        Coord i0 = Coord::floor(p);
        openvdb::Vec3d u = p - i0.asVec3d();
        openvdb::Vec3d c[2][2][2];
        for (int dx = 0; dx < 2; ++dx)
          for (int dy = 0; dy < 2; ++dy)
            for (int dz = 0; dz < 2; ++dz)
              c[dx][dy][dz] = openvdb::Vec3d(values_.Value(i0.offsetBy(dx, dy, dz)));
        auto lerp = [](const openvdb::Vec3d& a, const openvdb::Vec3d& b, double t) {
          return a + (b - a) * t;
        };
        openvdb::Vec3d x00 = lerp(c[0][0][0], c[0][0][1], u[2]);
        openvdb::Vec3d x01 = lerp(c[0][1][0], c[0][1][1], u[2]);
        openvdb::Vec3d x10 = lerp(c[1][0][0], c[1][0][1], u[2]);
        openvdb::Vec3d x11 = lerp(c[1][1][0], c[1][1][1], u[2]);
        v = lerp(lerp(x00, x01, u[1]), lerp(x10, x11, u[1]), u[0]);
      }
      if (++reads_ % 4096 == 0) values_.Clear();  // bound the private leaf cache
      return glm::vec3(float(v[0]), float(v[1]), float(v[2]));
    }

   private:
    const CGridT& grid_;
    const openvdb::math::Transform& main_;
    bool same_;
    PrivateReader<CGridT> values_;
    uint64_t reads_ = 0;
  };

  typename CGridT::Ptr grid_;
  const openvdb::math::Transform& main_;
  bool same_;
};

// ---------------------------------------------------------------------------
// The ingest of one float or double grid.

struct Context {
  const IngestOptions& options;
  const WriterFactory& factory;
  ProgressSink* progress;
  IngestStats* stats;
  LevelsChoice choice;
  StoreMeta meta;  // source, grid, class, transform, options filled in by the caller
  ColorSource* color = nullptr;
};

template <class GridT>
class GridIngest {
 public:
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;

  GridIngest(GridT& grid, Context& cx) : grid_(grid), tree_(grid.tree()), cx_(cx) {}

  Status Run() {
    const bool level_set = cx_.meta.grid_class == GridClass::kLevelSet;
    level_set_ = level_set;
    iso_ = ValueT(cx_.meta.isovalue);
    threshold_ = ValueT(cx_.meta.threshold);

    // 1. Topology.
    Stopwatch t0;
    uint64_t leaf_count = 0;
    for (auto it = tree_.beginLeaf(); it; ++it) {
      LeafT* leaf = it.getLeaf();
      ++leaf_count;
      if (leaf->isEmpty()) continue;  // no active voxel
      LeafInfo li;
      li.leaf = leaf;
      li.active = leaf->getNodeBoundingBox();  // bounds the active voxels; no per-voxel scan
      leaves_.push_back(li);
    }
    {
      auto it = tree_.cbeginValueOn();
      it.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1);  // tiles only
      for (; it; ++it) {
        if (!it.isTileValue()) continue;
        ++cx_.stats->active_tiles;
        if (!Occupied(*it)) continue;
        CoordBBox b;
        it.getBoundingBox(b);
        tiles_.push_back({b, *it});
        cx_.stats->occupied_tile_voxels += b.volume();
      }
    }
    cx_.stats->leaf_nodes = leaf_count;
    cx_.stats->active_voxels = tree_.activeVoxelCount();
    cx_.stats->seconds_open += t0.Seconds();
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
    auto writer_or = cx_.factory(cx_.options.output, meta, wo);
    if (!writer_or.ok()) return writer_or.status();
    std::unique_ptr<StoreWriter> writer = std::move(writer_or).value();

    // 4. Bricks.
    t0.Restart();
    if (!empty) {
      VOX_RETURN_IF_ERROR(BuildBrickMap(occ));
      VOX_RETURN_IF_ERROR(WriteBricks(writer.get()));
    }
    cx_.stats->seconds_bricks = t0.Seconds();
    // Streaming check: no leaf buffer was loaded into the tree itself.
    for (auto it = tree_.cbeginLeaf(); it; ++it)
      if (!it->buffer().isOutOfCore()) ++cx_.stats->leaves_resident_in_tree;
    t0.Restart();
    VOX_RETURN_IF_ERROR(writer->Finish());
    cx_.stats->seconds_finish = t0.Seconds();
    return OkStatus();
  }

 private:
  struct LeafInfo {
    LeafT* leaf = nullptr;
    CoordBBox active;    // bounds of its active voxels: the leaf's node box
    int state = 0;       // 0: not decoded, 1: decoded
    CoordBBox occupied;  // once decoded
  };
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

  void Message(const std::string& m) {
    if (cx_.progress) cx_.progress->Message(m);
  }

  // Decodes a leaf into a private buffer copy (the tree's leaf stays on disk).
  void DecodeOccupied(LeafInfo& li) {
    if (li.state) return;
    LeafValues<LeafT> values;
    const ValueT* d = values.Get(li.leaf);
    const Coord o = li.leaf->origin();
    for (auto m = li.leaf->getValueMask().beginOn(); m; ++m) {
      openvdb::Index n = m.pos();
      if (!Occupied(d[n])) continue;
      li.occupied.expand(o + Coord(int(n >> 6), int((n >> 3) & 7), int(n & 7)));
    }
    li.state = 1;
    ++cx_.stats->bbox_leaves_read;
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
      std::sort(order.begin(), order.end(), [&](uint32_t x, uint32_t y) {
        return leaves_[x].active.min()[a] < leaves_[y].active.min()[a];
      });
      for (uint32_t i : order) {
        LeafInfo& li = leaves_[i];
        if (li.active.min()[a] >= lo[a]) break;
        DecodeOccupied(li);
        if (!li.occupied.empty()) lo[a] = std::min<int64_t>(lo[a], li.occupied.min()[a]);
      }
      std::sort(order.begin(), order.end(), [&](uint32_t x, uint32_t y) {
        return leaves_[x].active.max()[a] > leaves_[y].active.max()[a];
      });
      for (uint32_t i : order) {
        LeafInfo& li = leaves_[i];
        if (li.active.max()[a] <= hi[a]) break;
        DecodeOccupied(li);
        if (!li.occupied.empty()) hi[a] = std::max<int64_t>(hi[a], li.occupied.max()[a]);
      }
      if (lo[a] == kBig) return CoordBBox();  // nothing occupied anywhere
    }
    return CoordBBox(Coord(int(lo[0]), int(lo[1]), int(lo[2])),
                     Coord(int(hi[0]), int(hi[1]), int(hi[2])));
  }

  static constexpr int kKeyBits = 21;
  static uint64_t Key(int64_t x, int64_t y, int64_t z) {
    return uint64_t(x) | (uint64_t(y) << kKeyBits) | (uint64_t(z) << (2 * kKeyBits));
  }
  static int64_t KeyCoord(uint64_t k, int a) {
    return int64_t((k >> (a * kKeyBits)) & ((uint64_t(1) << kKeyBits) - 1));
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
    std::unordered_map<uint64_t, uint32_t> index;
    auto brick = [&](int64_t x, int64_t y, int64_t z) -> BrickWork& {
      uint64_t k = Key(x, y, z);
      auto [it, inserted] = index.try_emplace(k, uint32_t(bricks_.size()));
      if (inserted) {
        bricks_.emplace_back();
        bricks_.back().key = k;
      }
      return bricks_[it->second];
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
    for (uint32_t i = 0; i < leaves_.size(); ++i) {
      if (!range(leaves_[i].active, lo, hi)) continue;
      for (int64_t z = lo[2]; z <= hi[2]; ++z)
        for (int64_t y = lo[1]; y <= hi[1]; ++y)
          for (int64_t x = lo[0]; x <= hi[0]; ++x) brick(x, y, z).leaves.push_back(i);
    }
    for (uint32_t i = 0; i < tiles_.size(); ++i) {
      if (!range(tiles_[i].box, lo, hi)) continue;
      for (int64_t z = lo[2]; z <= hi[2]; ++z)
        for (int64_t y = lo[1]; y <= hi[1]; ++y)
          for (int64_t x = lo[0]; x <= hi[0]; ++x) brick(x, y, z).tiles.push_back(i);
    }
    // Bricks in z, y, x order of their coordinates: neighbours stay close.
    std::sort(bricks_.begin(), bricks_.end(), [&](const BrickWork& p, const BrickWork& q) {
      for (int a : {2, 1, 0}) {
        int64_t u = KeyCoord(p.key, a), v = KeyCoord(q.key, a);
        if (u != v) return u < v;
      }
      return false;
    });
    return OkStatus();
  }

  // One brick's voxels. Runs concurrently on many bricks; reads leaf values
  // only through private decoded copies (see LeafValues).
  std::vector<BrickVoxel> ExtractBrick(const BrickWork& bw) {
    const int64_t size = int64_t(1) << B_;
    int64_t rmin[3], rmax[3];
    for (int a = 0; a < 3; ++a) {
      rmin[a] = origin_[a] + (KeyCoord(bw.key, a) << B_);
      rmax[a] = rmin[a] + size - 1;
    }
    std::vector<BrickVoxel> out;
    PrivateReader<GridT> reader(grid_);
    NoLeafAccessor<TreeT> acc(grid_.constTree());  // topology only: probes and tiles
    std::unique_ptr<ColorReader> color = cx_.color ? cx_.color->NewReader() : nullptr;
    auto normal_from = [](double gx, double gy, double gz) {
      double len = std::sqrt(gx * gx + gy * gy + gz * gz);
      if (!(len > 0) || !std::isfinite(len)) return glm::vec3(0.0f);
      return glm::vec3(float(gx / len), float(gy / len), float(gz / len));
    };

    // The leaf being visited and its six face neighbours, resolved lazily.
    struct Current {
      const LeafT* leaf = nullptr;
      const ValueT* d = nullptr;
      Coord o;
      const ValueT* nb[6];   // +x, -x, +y, -y, +z, -z: a neighbour leaf's values
      bool resolved[6];
    } cur;
    auto begin_leaf = [&](const LeafT* leaf) {
      cur.leaf = leaf;
      cur.d = reader.Leaf(leaf);
      cur.o = leaf->origin();
      for (int i = 0; i < 6; ++i) cur.resolved[i] = false;
    };
    // Value at leaf offset n moved one voxel along `axis` in direction `dir`
    // (+1/-1), from leaf-local coordinate l on that axis.
    static constexpr openvdb::Index kStride[3] = {64, 8, 1};
    auto step = [&](openvdb::Index n, int axis, int dir, int l) -> double {
      const int64_t stride = kStride[axis];
      if ((dir > 0 && l < 7) || (dir < 0 && l > 0)) return double(cur.d[int64_t(n) + dir * stride]);
      const int slot = 2 * axis + (dir > 0 ? 0 : 1);
      Coord c = cur.o + Coord(int(n >> 6), int((n >> 3) & 7), int(n & 7));
      c[axis] += dir;
      if (!cur.resolved[slot]) {
        const LeafT* nb = acc.probeConstLeaf(c);
        cur.nb[slot] = nb ? reader.Leaf(nb) : nullptr;
        cur.resolved[slot] = true;
      }
      if (cur.nb[slot]) return double(cur.nb[slot][LeafT::coordToOffset(c)]);
      return double(acc.getValue(c));  // a tile or the background
    };
    // One active voxel at leaf offset n of the current leaf.
    auto visit = [&](openvdb::Index n, bool check_region) {
      const int lx = int(n >> 6), ly = int((n >> 3) & 7), lz = int(n & 7);
      const int64_t x = int64_t(cur.o.x()) + lx, y = int64_t(cur.o.y()) + ly,
                    z = int64_t(cur.o.z()) + lz;
      if (check_region && (x < rmin[0] || x > rmax[0] || y < rmin[1] || y > rmax[1] ||
                           z < rmin[2] || z > rmax[2]))
        return;
      const ValueT v = cur.d[n];
      if (!Occupied(v)) return;
      BrickVoxel bv;
      bv.x = uint32_t(x - rmin[0]);
      bv.y = uint32_t(y - rmin[1]);
      bv.z = uint32_t(z - rmin[2]);
      if (level_set_) {
        // Central differences in index space.
        bv.attr.normal = normal_from(step(n, 0, 1, lx) - step(n, 0, -1, lx),
                                     step(n, 1, 1, ly) - step(n, 1, -1, ly),
                                     step(n, 2, 1, lz) - step(n, 2, -1, lz));
      } else {
        bv.attr.density = float(v);
      }
      if (color) bv.attr.color = color->At(Coord{int(x), int(y), int(z)});
      out.push_back(bv);
    };

    // Fast path: bricks of at least 8^3 without tiles hold whole leaves
    // (the origin is aligned to the brick size); visiting the leaves in
    // Morton order and each leaf's voxels in Morton order gives the voxels
    // in the writer's order without a sort.
    const bool morton_walk = B_ >= 3 && bw.tiles.empty();
    if (morton_walk) {
      std::vector<std::pair<uint64_t, const LeafT*>> order;
      order.reserve(bw.leaves.size());
      uint64_t expected = 0;
      for (uint32_t li_index : bw.leaves) {
        const LeafT* leaf = leaves_[li_index].leaf;
        const Coord o = leaf->origin();
        order.push_back({MortonKey21(uint64_t(o.x() - rmin[0]) >> 3,
                                     uint64_t(o.y() - rmin[1]) >> 3,
                                     uint64_t(o.z() - rmin[2]) >> 3),
                         leaf});
        expected += leaf->onVoxelCount();
      }
      std::sort(order.begin(), order.end());
      out.reserve(size_t(expected));
      const auto& table = MortonLeafOrder();
      for (const auto& [key, leaf] : order) {
        begin_leaf(leaf);
        const auto& mask = leaf->getValueMask();
        for (uint16_t n : table)
          if (mask.isOn(n)) visit(n, false);
      }
      return out;
    }
    for (uint32_t li_index : bw.leaves) {
      begin_leaf(leaves_[li_index].leaf);
      for (auto m = cur.leaf->getValueMask().beginOn(); m; ++m) visit(m.pos(), true);
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
          for (int64_t z = lo[2]; z <= hi[2]; ++z) {
            BrickVoxel bv;
            bv.x = uint32_t(x - rmin[0]);
            bv.y = uint32_t(y - rmin[1]);
            bv.z = uint32_t(z - rmin[2]);
            const Coord ijk{int(x), int(y), int(z)};
            if (level_set_) {
              auto g = [&](int dx, int dy, int dz) {
                return double(reader.Value(ijk.offsetBy(dx, dy, dz))) -
                       double(reader.Value(ijk.offsetBy(-dx, -dy, -dz)));
              };
              bv.attr.normal = normal_from(g(1, 0, 0), g(0, 1, 0), g(0, 0, 1));
            } else {
              bv.attr.density = float(t.value);
            }
            if (color) bv.attr.color = color->At(ijk);
            out.push_back(bv);
          }
    }
    SortMorton(&out);
    return out;
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

  // Puts a brick's voxels in the octree's Morton order (octal digit x | y<<1 |
  // z<<2), which the writer builds its cells in, so its sort finds them sorted.
  static void SortMorton(std::vector<BrickVoxel>* v) {
    if (v->size() < 2) return;
    std::vector<std::pair<uint64_t, uint32_t>> keys(v->size());
    for (size_t i = 0; i < v->size(); ++i) {
      const BrickVoxel& b = (*v)[i];
      keys[i] = {MortonKey21(b.x, b.y, b.z), uint32_t(i)};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<BrickVoxel> sorted(v->size());
    for (size_t i = 0; i < keys.size(); ++i) sorted[i] = (*v)[keys[i].second];
    v->swap(sorted);
  }

  // Bricks go through a pipeline: the parallel stage builds a brick's voxels
  // and hands them to the writer (AddBrick is thread-safe: it encodes and
  // compresses in the calling thread); the serial in-order stage reports
  // progress.
  Status WriteBricks(StoreWriter* writer) {
    struct Item {
      size_t index = 0;
      size_t voxels = 0;
    };
    const size_t total = bricks_.size();
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
    size_t next = 0, written = 0;
    uint64_t voxels_done = 0;
    const size_t tokens = size_t(std::max(2, 2 * tbb::this_task_arena::max_concurrency()));
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, Item>(
            tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) -> Item {
              if (next >= total || failed.load()) {
                fc.stop();
                return Item{};
              }
              return Item{next++, 0};
            }) &
            tbb::make_filter<Item, Item>(
                tbb::filter_mode::parallel,
                [&](Item it) -> Item {
                  if (failed.load()) return it;
                  const BrickWork& bw = bricks_[it.index];
                  try {
                    std::vector<BrickVoxel> voxels = ExtractBrick(bw);
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
                  return it;
                }) &
            tbb::make_filter<Item, void>(
                tbb::filter_mode::serial_in_order, [&](Item it) {
                  if (failed.load()) return;
                  voxels_done += it.voxels;
                  if (it.voxels) ++written;
                  if (cx_.progress) cx_.progress->Progress(it.index + 1, total, voxels_done);
                }));
    if (!first_error.ok()) return first_error;
    cx_.stats->occupied_voxels = voxels_done;
    cx_.stats->bricks = written;
    return OkStatus();
  }

  GridT& grid_;
  TreeT& tree_;
  Context& cx_;
  bool level_set_ = true;
  ValueT iso_{}, threshold_{};
  std::vector<LeafInfo> leaves_;  // leaves with active voxels
  std::vector<Tile> tiles_;       // occupied active tiles
  int B_ = 0;
  int64_t origin_[3] = {0, 0, 0};
  std::vector<BrickWork> bricks_;
};

// ---------------------------------------------------------------------------
// The VDB file's outer layout, checked before OpenVDB reads it: OpenVDB trusts
// the lengths it reads, so a truncated file can make it allocate gigabytes
// for a garbage string. This walks the header, the file metadata and the grid
// descriptors (each with its grid's [start, end) offsets) and checks every
// length and offset against the file size. Grid contents are left to OpenVDB.

// A descriptor's unique name: the grid name, with a "\x1e<n>" suffix when not unique.
std::string GridDescriptorName(const std::string& unique) {
  return unique.substr(0, unique.find('\x1e'));
}

class LayoutReader {
 public:
  LayoutReader(std::FILE* f, uint64_t size, const std::string& path)
      : f_(f), size_(size), path_(path) {}

  Status Read(void* p, uint64_t n, const char* what) {
    if (pos_ + n > size_ || std::fread(p, 1, n, f_) != n)
      return Truncated(what);
    pos_ += n;
    return OkStatus();
  }
  Status Skip(uint64_t n, const char* what) {
    if (n > size_ - pos_) return Truncated(what);
    return Seek(pos_ + n, what);
  }
  Status Seek(uint64_t p, const char* what) {
    if (p > size_) return Truncated(what);
    if (std::fseek(f_, long(p), SEEK_SET) != 0) return IoError(path_ + ": " + std::strerror(errno));
    pos_ = p;
    return OkStatus();
  }
  // A length-prefixed string (uint32 length + bytes).
  Status String(std::string* s, const char* what) {
    uint32_t n = 0;
    VOX_RETURN_IF_ERROR(Read(&n, 4, what));
    if (n > size_ - pos_) return Truncated(what);
    s->resize(n);
    return Read(s->data(), n, what);
  }
  Status Truncated(const char* what) const {
    return CorruptionError(path_ + ": truncated or corrupt VDB file: " + what + " at byte " +
                           std::to_string(pos_) + " runs past the end of the file (" +
                           std::to_string(size_) + " bytes)");
  }
  uint64_t pos() const { return pos_; }
  uint64_t size() const { return size_; }

 private:
  std::FILE* f_;
  uint64_t size_;
  const std::string& path_;
  uint64_t pos_ = 0;
};

Status CheckVdbLayout(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return IoError(path + ": " + std::strerror(errno));
  struct Closer {
    std::FILE* f;
    ~Closer() { std::fclose(f); }
  } closer{f};
  struct stat st;
  if (::fstat(fileno(f), &st) != 0) return IoError(path + ": " + std::strerror(errno));
  LayoutReader r(f, uint64_t(st.st_size), path);
  int64_t magic = 0;
  if (uint64_t(st.st_size) < 8 || !r.Read(&magic, 8, "magic").ok() ||
      magic != int64_t(openvdb::OPENVDB_MAGIC))
    return CorruptionError(path + ": not a readable OpenVDB file (no VDB magic number)");
  uint32_t version = 0;
  VOX_RETURN_IF_ERROR(r.Read(&version, 4, "file version"));
  if (version < 211) {
    VOX_RETURN_IF_ERROR(r.Skip(8, "file version"));
    return OkStatus();  // pre-2.1.1 files: left to OpenVDB
  }
  VOX_RETURN_IF_ERROR(r.Skip(8, "library version"));
  char has_offsets = 1;
  if (version >= 212) VOX_RETURN_IF_ERROR(r.Read(&has_offsets, 1, "grid offsets flag"));
  if (version >= 220 && version < 222) VOX_RETURN_IF_ERROR(r.Skip(1, "compression flag"));
  VOX_RETURN_IF_ERROR(r.Skip(version >= 218 ? 36 : 16, "file UUID"));
  // File metadata: count, then (name, type name, size-prefixed value).
  int32_t count = 0;
  VOX_RETURN_IF_ERROR(r.Read(&count, 4, "file metadata count"));
  if (count < 0 || uint64_t(count) > r.size()) return r.Truncated("file metadata count");
  std::string s;
  for (int32_t i = 0; i < count; ++i) {
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata name"));
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata type"));
    VOX_RETURN_IF_ERROR(r.String(&s, "file metadata value"));
  }
  if (!has_offsets) return OkStatus();  // a stream without offsets: left to OpenVDB
  int32_t grids = 0;
  VOX_RETURN_IF_ERROR(r.Read(&grids, 4, "grid count"));
  if (grids < 0 || uint64_t(grids) > r.size()) return r.Truncated("grid count");
  for (int32_t g = 0; g < grids; ++g) {
    std::string name;
    VOX_RETURN_IF_ERROR(r.String(&name, "grid name"));
    VOX_RETURN_IF_ERROR(r.String(&s, "grid type"));
    if (version >= 216) VOX_RETURN_IF_ERROR(r.String(&s, "instance parent name"));
    int64_t pos[3];
    VOX_RETURN_IF_ERROR(r.Read(pos, sizeof pos, "grid offsets"));
    if (pos[0] < int64_t(r.pos()) || pos[1] < pos[0] || pos[2] < pos[1] ||
        uint64_t(pos[2]) > r.size())
      return CorruptionError(path + ": truncated or corrupt VDB file: grid " +
                             Quote(GridDescriptorName(name)) + " spans bytes " +
                             std::to_string(pos[0]) + ".." + std::to_string(pos[2]) +
                             " of a " + std::to_string(r.size()) + "-byte file");
    VOX_RETURN_IF_ERROR(r.Seek(uint64_t(pos[2]), "next grid descriptor"));
  }
  return OkStatus();
}

std::string GridTypeLabel(const openvdb::GridBase& g) {
  return g.valueType() + (g.isType<openvdb::points::PointDataGrid>() ? " (points)" : "");
}

bool IsScalar(const openvdb::GridBase& g) {
  return g.isType<openvdb::FloatGrid>() || g.isType<openvdb::DoubleGrid>();
}

std::string ListGrids(const openvdb::GridPtrVec& grids) {
  std::string s;
  for (const auto& g : grids) {
    if (!s.empty()) s += ", ";
    s += Quote(g->getName()) + " (" + GridTypeLabel(*g) + ", " +
         openvdb::GridBase::gridClassToString(g->getGridClass()) + ")";
  }
  return s.empty() ? "none" : s;
}

std::string FormatDouble(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

StatusOr<IngestStats> IngestImpl(const IngestOptions& o, const WriterFactory& factory,
                                 ProgressSink* progress) {
  const Stopwatch t_start;
  IngestStats stats;
  if (o.input.empty()) return InvalidArgumentError("no input .vdb file given");
  if (o.output.empty()) return InvalidArgumentError("no output store directory given");
  if (o.zstd_level < 1 || o.zstd_level > 22)
    return InvalidArgumentError("zstd level " + std::to_string(o.zstd_level) + " outside 1..22");
  if (o.normal_bits < 8 || o.normal_bits > 16)
    return InvalidArgumentError("normal precision " + std::to_string(o.normal_bits) +
                                " bits outside 8..16");
  if (o.threads < 0) return InvalidArgumentError("thread count must be >= 0 (0: all cores)");
  if (o.isovalue && o.threshold)
    return InvalidArgumentError(
        "--isovalue (level sets) and --threshold (fog volumes) exclude each other");
  if (o.isovalue && !std::isfinite(*o.isovalue))
    return InvalidArgumentError("isovalue must be finite");
  if (o.threshold && !std::isfinite(*o.threshold))
    return InvalidArgumentError("threshold must be finite");
  VOX_ASSIGN_OR_RETURN(LevelsChoice choice, ParseLevels(o.levels));

  struct stat st;
  if (::stat(o.input.c_str(), &st) != 0)
    return errno == ENOENT ? NotFoundError(o.input + ": no such file")
                           : IoError(o.input + ": " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return InvalidArgumentError(o.input + ": not a regular file");
  stats.input_bytes = uint64_t(st.st_size);
  // Refuse an existing target before the (long) read; the writer checks again.
  if (!o.force && ::access(o.output.c_str(), F_OK) == 0)
    return InvalidArgumentError(o.output + ": already exists; pass --force to replace it");

  Stopwatch t0;
  VOX_RETURN_IF_ERROR(CheckVdbLayout(o.input));
  InitOpenVdb();
  openvdb::io::File file(o.input);
  file.setCopyMaxBytes(0);  // read the file in place, no private copy
  try {
    file.open(/*delayLoad=*/true);
  } catch (const openvdb::Exception& e) {
    return CorruptionError(o.input + ": not a readable OpenVDB file (" + e.what() + ")");
  }
  openvdb::GridPtrVecPtr grids = file.readAllGridMetadata();
  // The grid.
  openvdb::GridBase::Ptr meta_grid;
  if (!o.grid_name.empty()) {
    for (const auto& g : *grids)
      if (g->getName() == o.grid_name) {
        meta_grid = g;
        break;
      }
    if (!meta_grid)
      return NotFoundError(o.input + ": no grid named " + Quote(o.grid_name) +
                           "; the file has: " + ListGrids(*grids));
  } else {
    for (const auto& g : *grids)
      if (IsScalar(*g)) {
        meta_grid = g;
        break;
      }
    if (!meta_grid)
      return NotFoundError(o.input + ": no float or double grid to ingest; the file has: " +
                           ListGrids(*grids));
  }
  const std::string name = meta_grid->getName();
  const std::string where = "grid " + Quote(name) + " in " + o.input;
  if (!IsScalar(*meta_grid))
    return UnsupportedError(where + " holds " + GridTypeLabel(*meta_grid) +
                            " values; vox ingests float and double grids (level sets and fog "
                            "volumes)");
  if (!meta_grid->transform().isLinear())
    return UnsupportedError(where + " has a non-linear (" + meta_grid->transform().mapType() +
                            ") transform; vox needs a linear (affine) one");

  Context cx{o, factory, progress, &stats, choice, StoreMeta{}, nullptr};
  StoreMeta& meta = cx.meta;
  meta.source_file = o.input;
  meta.grid_name = name;
  switch (meta_grid->getGridClass()) {
    case openvdb::GRID_LEVEL_SET:
      if (o.threshold)
        return InvalidArgumentError(where + " is a level set; --threshold applies to fog volumes "
                                    "(use --isovalue)");
      meta.grid_class = GridClass::kLevelSet;
      break;
    case openvdb::GRID_FOG_VOLUME:
      if (o.isovalue)
        return InvalidArgumentError(where + " is a fog volume; --isovalue applies to level sets "
                                    "(use --threshold)");
      meta.grid_class = GridClass::kFogVolume;
      break;
    default:
      if (o.threshold) {
        meta.grid_class = GridClass::kFogVolume;
      } else if (o.isovalue) {
        meta.grid_class = GridClass::kLevelSet;
      } else {
        return InvalidArgumentError(
            where + " has grid class " +
            Quote(openvdb::GridBase::gridClassToString(meta_grid->getGridClass())) +
            "; pass --threshold F to read it as a fog volume or --isovalue F as a level set");
      }
  }
  meta.isovalue = o.isovalue.value_or(0.0);
  meta.threshold = o.threshold.value_or(0.0);
  meta.has_normal = meta.grid_class == GridClass::kLevelSet;
  meta.has_density = meta.grid_class == GridClass::kFogVolume;
  const openvdb::math::Mat4d m = meta_grid->transform().baseMap()->getAffineMap()->getMat4();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) meta.index_to_world[i][j] = m(i, j);  // row vectors: same indices
  const openvdb::Vec3d vs = meta_grid->transform().voxelSize();
  meta.voxel_size = std::max({vs[0], vs[1], vs[2]});
  meta.build_options = o.command_line;
  if (meta.build_options.empty()) {
    meta.build_options = "levels=" + o.levels + " zstd_level=" + std::to_string(o.zstd_level);
    if (o.isovalue) meta.build_options += " isovalue=" + FormatDouble(*o.isovalue);
    if (o.threshold) meta.build_options += " threshold=" + FormatDouble(*o.threshold);
    if (!o.color_grid.empty()) meta.build_options += " color=" + o.color_grid;
    if (o.normal_bits != 16) meta.build_options += " normal_bits=" + std::to_string(o.normal_bits);
  }

  // The colour grid.
  openvdb::GridBase::Ptr color_meta;
  if (!o.color_grid.empty()) {
    for (const auto& g : *grids)
      if (g->getName() == o.color_grid) color_meta = g;
    if (!color_meta)
      return NotFoundError(o.input + ": no colour grid named " + Quote(o.color_grid) +
                           "; the file has: " + ListGrids(*grids));
    const std::string cwhere = "colour grid " + Quote(o.color_grid) + " in " + o.input;
    if (!color_meta->isType<openvdb::Vec3fGrid>() && !color_meta->isType<openvdb::Vec3dGrid>())
      return UnsupportedError(cwhere + " holds " + GridTypeLabel(*color_meta) +
                              " values; a colour grid holds vec3s or vec3d");
    if (!color_meta->transform().isLinear())
      return UnsupportedError(cwhere + " has a non-linear transform");
  }

  if (progress) progress->Message("reading the topology of " + where);
  openvdb::GridBase::Ptr base = file.readGrid(name);
  const openvdb::math::Transform& xform = base->transform();
  std::unique_ptr<ColorSource> color;
  if (color_meta) {
    openvdb::GridBase::Ptr cbase = file.readGrid(o.color_grid);
    if (auto cg = openvdb::gridPtrCast<openvdb::Vec3fGrid>(cbase))
      color = std::make_unique<TypedColorSource<openvdb::Vec3fGrid>>(cg, xform);
    else
      color = std::make_unique<TypedColorSource<openvdb::Vec3dGrid>>(
          openvdb::gridPtrCast<openvdb::Vec3dGrid>(cbase), xform);
    meta.has_color = true;
    cx.color = color.get();
  }
  stats.seconds_open = t0.Seconds();

  const int threads = o.threads > 0 ? o.threads : tbb::this_task_arena::max_concurrency();
  stats.threads = threads;
  tbb::task_arena arena(threads);
  Status s;
  arena.execute([&] {
    if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(base)) {
      s = GridIngest<openvdb::FloatGrid>(*fg, cx).Run();
    } else if (auto dg = openvdb::gridPtrCast<openvdb::DoubleGrid>(base)) {
      s = GridIngest<openvdb::DoubleGrid>(*dg, cx).Run();
    } else {
      s = InternalError(where + ": grid type changed between metadata and read");
    }
  });
  if (!s.ok()) return s;
  stats.seconds_total = t_start.Seconds();
  if (progress) progress->Done();
  return stats;
}

}  // namespace

StatusOr<LevelsChoice> ParseLevels(std::string_view text) {
  LevelsChoice c;
  if (text == "auto") return c;
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("--levels " + std::string(text) + ": " + why +
                                " (expected auto or N1+N2, e.g. 12+5)");
  };
  size_t plus = text.find('+');
  if (plus == std::string_view::npos) return bad("no '+'");
  auto num = [](std::string_view s, int* out) {
    if (s.empty() || s.size() > 3) return false;
    int v = 0;
    for (char ch : s) {
      if (ch < '0' || ch > '9') return false;
      v = v * 10 + (ch - '0');
    }
    *out = v;
    return true;
  };
  int n1 = 0, n2 = 0;
  if (!num(text.substr(0, plus), &n1) || !num(text.substr(plus + 1), &n2))
    return bad("N1 and N2 must be whole numbers");
  if (n1 < 1 || n2 < 1) return bad("each step needs at least one level");
  if (n1 > kMaxStepLevels || n2 > kMaxStepLevels) return bad("each step holds at most 20 levels");
  if (n1 + n2 > kMaxLevels) return bad("at most 40 levels in all");
  c.automatic = false;
  c.brick_level = n1;
  c.brick_depth = n2;
  return c;
}

StatusOr<Placement> PlaceGrid(const int64_t bmin[3], const int64_t bmax[3],
                              const LevelsChoice& choice) {
  Placement p;
  const bool empty = bmin[0] > bmax[0] || bmin[1] > bmax[1] || bmin[2] > bmax[2];
  constexpr int kAutoBrickDepth = 5;
  int b = choice.automatic ? kAutoBrickDepth : choice.brick_depth;
  if (empty) {
    p.brick_level = choice.automatic ? 1 : choice.brick_level;
    p.levels = p.brick_level + b;
    return p;
  }
  for (;;) {
    uint64_t extent = 1;
    for (int a = 0; a < 3; ++a) {
      p.origin[a] = AlignDown(bmin[a], b);
      extent = std::max<uint64_t>(extent, uint64_t(bmax[a] - p.origin[a] + 1));
    }
    const int cover = CeilLog2(extent);
    if (!choice.automatic) {
      p.levels = choice.brick_level + b;
      p.brick_level = choice.brick_level;
      if (cover > p.levels)
        return InvalidArgumentError(
            "--levels " + std::to_string(choice.brick_level) + "+" + std::to_string(b) +
            " covers 2^" + std::to_string(p.levels) + " voxels per axis, but the occupied bbox "
            "(with the origin aligned to the brick size) needs 2^" + std::to_string(cover));
      return p;
    }
    p.levels = std::max(cover, b + 1);
    if (p.levels > kMaxLevels)
      return InvalidArgumentError("the occupied bbox needs 2^" + std::to_string(p.levels) +
                                  " voxels per axis; vox handles at most 2^40");
    if (p.levels - b > kMaxStepLevels) {
      b = p.levels - kMaxStepLevels;  // deeper bricks; realign and measure again
      continue;
    }
    p.brick_level = p.levels - b;
    return p;
  }
}

StatusOr<IngestStats> IngestWithWriter(const IngestOptions& options, const WriterFactory& factory,
                                       ProgressSink* progress) {
  try {
    return IngestImpl(options, factory, progress);
  } catch (const openvdb::Exception& e) {
    return CorruptionError(options.input + ": OpenVDB cannot read it: " + e.what());
  } catch (const std::bad_alloc&) {
    return ResourceExhaustedError("out of memory ingesting " + options.input +
                                  " (a corrupt file can make OpenVDB ask for huge allocations)");
  } catch (const std::exception& e) {
    return InternalError("ingesting " + options.input + ": " + e.what());
  }
}

}  // namespace vox

// The one place a brick's voxel is built: its brick-local coordinates, its
// level-set normal (the distance field's central differences in index space,
// normalised; 0 where the gradient vanishes or is not finite) or fog density,
// and its colour. Voxels come from leaves (FromLeaf: the leaf's decoded values
// and its six face neighbours, resolved once per leaf) or from active tiles
// (FromTile: any value looked up through the tree's topology); both give the
// same voxel for the same coordinate and value. Private to ingest and its tests.
//
// Where values come from is a Source: GridSource reads an OpenVDB grid
// (through private leaf copies), TopologySource a CompactTopology (leaves
// decoded from the file). Both give the same voxels for the same grid.
//
// Thread safety: one VoxelBuilder per thread (it holds private leaf copies);
// many may read the same const grid or topology at once.
#ifndef VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_
#define VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_

#include <cmath>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include <glm/glm.hpp>
#include <openvdb/openvdb.h>

#include "ingest/internal/color.h"
#include "ingest/internal/leaf_values.h"
#include "ingest/internal/vdb_topology.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox::ingest_internal {

// Values of an OpenVDB grid read with delayed loading: leaves decoded privately.
template <class GridT>
class GridSource {
 public:
  using Init = GridT;
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;
  using LeafRef = const LeafT*;

  explicit GridSource(const GridT& grid) : reader_(grid), acc_(grid.constTree()) {}
  const ValueT* Values(LeafRef leaf) { return reader_.Leaf(leaf); }
  const openvdb::util::NodeMask<3>& Mask(LeafRef leaf) { return leaf->getValueMask(); }
  openvdb::Coord Origin(LeafRef leaf) const { return leaf->origin(); }
  // The leaf holding c (true), else c's tile or background value in *value.
  bool Probe(const openvdb::Coord& c, LeafRef* leaf, ValueT* value) {
    *leaf = acc_.probeConstLeaf(c);
    if (*leaf) return true;
    *value = acc_.getValue(c);  // a tile or the background: no leaf buffer involved
    return false;
  }

 private:
  PrivateReader<GridT> reader_;
  NoLeafAccessor<TreeT> acc_;  // topology only: probes and tiles
};

// Values of a CompactTopology: leaves decoded from the file, kept until
// Clear().
template <class ValueT_>
class TopologySource {
 public:
  using ValueT = ValueT_;
  using Init = CompactTopology<ValueT>;
  using LeafRef = uint32_t;  // index into Init::leaves()

  explicit TopologySource(const Init& topology) : t_(topology) {}
  const ValueT* Values(LeafRef leaf) { return Get(leaf).values; }
  const openvdb::util::NodeMask<3>& Mask(LeafRef leaf) { return Get(leaf).mask; }
  openvdb::Coord Origin(LeafRef leaf) const { return t_.leaves()[leaf].Origin(); }
  bool Probe(const openvdb::Coord& c, LeafRef* leaf, ValueT* value) {
    const auto w = t_.Lookup(c);
    if (w.leaf >= 0) {
      *leaf = LeafRef(w.leaf);
      return true;
    }
    *value = w.value;
    return false;
  }
  void Clear() { decoded_.clear(); }
  size_t decoded() const { return decoded_.size(); }

 private:
  struct Decoded {
    openvdb::util::NodeMask<3> mask;
    ValueT values[512];
  };
  const Decoded& Get(LeafRef leaf) {
    auto [it, inserted] = decoded_.try_emplace(leaf);
    if (inserted) {
      it->second = std::make_unique<Decoded>();
      try {
        t_.ReadLeaf(leaf, it->second->values, &it->second->mask, &scratch_);
      } catch (...) {
        decoded_.erase(it);
        throw;
      }
    }
    return *it->second;
  }
  const Init& t_;
  std::unordered_map<LeafRef, std::unique_ptr<Decoded>> decoded_;
  std::vector<char> scratch_;
};

template <class Source>
class BasicVoxelBuilder {
 public:
  using ValueT = typename Source::ValueT;
  using LeafRef = typename Source::LeafRef;

  // Voxels of the brick whose first (lowest) index coordinate is
  // `region_min`; `level_set` chooses normals over densities; `color` may be
  // null (no colour).
  BasicVoxelBuilder(const typename Source::Init& values, bool level_set, ColorReader* color,
                    const int64_t region_min[3])
      : source_(values), level_set_(level_set), color_(color) {
    for (int a = 0; a < 3; ++a) rmin_[a] = region_min[a];
  }

  Source& source() { return source_; }
  // A second scalar grid read as each voxel's temperature (null: none).
  void SetTemperature(ColorReader* temperature) { temperature_ = temperature; }

  // Leaf path. The voxels of `leaf` follow; its values are decoded privately
  // (may throw an OpenVDB exception for corrupt data).
  void BeginLeaf(LeafRef leaf) {
    d_ = source_.Values(leaf);
    o_ = source_.Origin(leaf);
    for (int i = 0; i < 6; ++i) resolved_[i] = false;
  }
  // The current leaf's value at offset n (x << 6 | y << 3 | z).
  ValueT LeafValue(openvdb::Index n) const { return d_[n]; }
  // The voxel at offset n of the current leaf, whose value is v.
  BrickVoxel FromLeaf(openvdb::Index n, ValueT v) {
    const int l[3] = {int(n >> 6), int((n >> 3) & 7), int(n & 7)};
    return Build(o_.offsetBy(l[0], l[1], l[2]), v, [&](int axis) {
      return Step(n, axis, 1, l[axis]) - Step(n, axis, -1, l[axis]);
    });
  }

  // Tile path: the voxel at `ijk` of an active tile of value v.
  BrickVoxel FromTile(const openvdb::Coord& ijk, ValueT v) {
    return Build(ijk, v, [&](int axis) {
      openvdb::Coord d(0, 0, 0);
      d[axis] = 1;
      return double(Value(ijk + d)) - double(Value(ijk - d));
    });
  }

 private:
  ValueT Value(const openvdb::Coord& c) {
    LeafRef leaf;
    ValueT v;
    if (source_.Probe(c, &leaf, &v)) return source_.Values(leaf)[LeafOffset(c)];
    return v;
  }
  static openvdb::Index LeafOffset(const openvdb::Coord& c) {
    return openvdb::Index(((c.x() & 7) << 6) | ((c.y() & 7) << 3) | (c.z() & 7));
  }

  // `diff(axis)`: value one voxel up minus one voxel down along `axis`.
  template <class Diff>
  BrickVoxel Build(const openvdb::Coord& ijk, ValueT v, Diff&& diff) {
    BrickVoxel bv;
    bv.x = uint32_t(int64_t(ijk.x()) - rmin_[0]);
    bv.y = uint32_t(int64_t(ijk.y()) - rmin_[1]);
    bv.z = uint32_t(int64_t(ijk.z()) - rmin_[2]);
    if (level_set_) {
      const double gx = diff(0), gy = diff(1), gz = diff(2);
      const double len = std::sqrt(gx * gx + gy * gy + gz * gz);
      bv.attr.normal = !(len > 0) || !std::isfinite(len)
                           ? glm::vec3(0.0f)
                           : glm::vec3(float(gx / len), float(gy / len), float(gz / len));
    } else {
      bv.attr.density = float(v);
    }
    if (color_) bv.attr.color = color_->At(ijk);
    if (temperature_) bv.attr.temperature = temperature_->At(ijk).x;
    return bv;
  }

  // The value at leaf offset n moved one voxel along `axis` in direction
  // `dir` (+1/-1), from leaf-local coordinate l on that axis.
  double Step(openvdb::Index n, int axis, int dir, int l) {
    static constexpr int64_t kStride[3] = {64, 8, 1};
    if ((dir > 0 && l < 7) || (dir < 0 && l > 0))
      return double(d_[int64_t(n) + dir * kStride[axis]]);
    const int slot = 2 * axis + (dir > 0 ? 0 : 1);  // +x, -x, +y, -y, +z, -z
    openvdb::Coord c = o_ + openvdb::Coord(int(n >> 6), int((n >> 3) & 7), int(n & 7));
    c[axis] += dir;
    if (!resolved_[slot]) {
      LeafRef nb;
      nb_[slot] = source_.Probe(c, &nb, &nb_value_[slot]) ? source_.Values(nb) : nullptr;
      resolved_[slot] = true;
    }
    if (nb_[slot]) return double(nb_[slot][LeafOffset(c)]);
    // The 8^3 block beside the face is one tile (or background) throughout.
    return double(nb_value_[slot]);
  }

  Source source_;
  bool level_set_;
  ColorReader* color_;
  ColorReader* temperature_ = nullptr;
  int64_t rmin_[3];
  // The leaf being visited and its face neighbours' values, resolved lazily.
  const ValueT* d_ = nullptr;
  openvdb::Coord o_;
  const ValueT* nb_[6] = {};
  ValueT nb_value_[6] = {};
  bool resolved_[6] = {};
};

// The builder over an OpenVDB grid.
template <class GridT>
using VoxelBuilder = BasicVoxelBuilder<GridSource<GridT>>;

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_

// The one place a brick's voxel is built: its brick-local coordinates, its
// level-set normal (the distance field's central differences in index space,
// normalised; 0 where the gradient vanishes or is not finite) or fog density,
// and its colour. Voxels come from leaves (FromLeaf: the leaf's decoded values
// and its six face neighbours, resolved once per leaf) or from active tiles
// (FromTile: any value looked up through the tree's topology); both give the
// same voxel for the same coordinate and value. Private to ingest and its tests.
//
// Thread safety: one VoxelBuilder per thread (it holds private leaf copies);
// many may read the same const grid at once.
#ifndef VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_
#define VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_

#include <cmath>
#include <cstdint>

#include <glm/glm.hpp>
#include <openvdb/openvdb.h>

#include "ingest/internal/color.h"
#include "ingest/internal/leaf_values.h"
#include "storage/store.h"

namespace vox::ingest_internal {

template <class GridT>
class VoxelBuilder {
 public:
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;

  // Voxels of the brick whose first (lowest) index coordinate is
  // `region_min`; `level_set` chooses normals over densities; `color` may be
  // null (no colour).
  VoxelBuilder(const GridT& grid, bool level_set, ColorReader* color,
               const int64_t region_min[3])
      : reader_(grid), acc_(grid.constTree()), level_set_(level_set), color_(color) {
    for (int a = 0; a < 3; ++a) rmin_[a] = region_min[a];
  }

  // Leaf path. The voxels of `leaf` follow; its values are decoded privately
  // (may throw an OpenVDB exception for corrupt data).
  void BeginLeaf(const LeafT* leaf) {
    d_ = reader_.Leaf(leaf);
    o_ = leaf->origin();
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
      return double(reader_.Value(ijk + d)) - double(reader_.Value(ijk - d));
    });
  }

 private:
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
      const LeafT* nb = acc_.probeConstLeaf(c);
      nb_[slot] = nb ? reader_.Leaf(nb) : nullptr;
      resolved_[slot] = true;
    }
    if (nb_[slot]) return double(nb_[slot][LeafT::coordToOffset(c)]);
    return double(acc_.getValue(c));  // a tile or the background
  }

  PrivateReader<GridT> reader_;
  NoLeafAccessor<TreeT> acc_;  // topology only: probes and tiles
  bool level_set_;
  ColorReader* color_;
  int64_t rmin_[3];
  // The leaf being visited and its face neighbours' values, resolved lazily.
  const ValueT* d_ = nullptr;
  openvdb::Coord o_;
  const ValueT* nb_[6] = {};
  bool resolved_[6] = {};
};

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_VOXEL_BUILDER_H_

// The pyramid's reducers (storage/lod.h): the sums a coarse cell keeps of
// its base voxels, and the cascade of run reducers that turns base voxels
// in Morton order into every level's coarse voxels. BuildLod and LodStream
// both reduce here, so their pyramids agree bit for bit.
#ifndef VOX_STORAGE_INTERNAL_LOD_REDUCE_H_
#define VOX_STORAGE_INTERNAL_LOD_REDUCE_H_

#include <cmath>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "core/util/status.h"
#include "storage/store.h"
#include "storage/store_writer.h"

namespace vox {
namespace storage_internal {

// What a cell needs from its voxels: sums over its occupied base voxels.
// The normal is area-weighted: only surface voxels (level sets: an occupied
// voxel whose neighbour along the dominant axis of its normal, outwards, is
// not occupied) count, each by the area of surface its column holds,
// 1 / max |n_a|. The voxels deeper in the band carry no surface, and their
// normals are the least accurate (their central differences reach past the
// narrow band, where values are clamped). A cell without a surface voxel
// takes the mean of all its voxels' normals.
struct Aggregate {
  uint64_t count = 0;       // occupied base voxels
  glm::dvec3 normal{0.0};   // sum of their unit normals
  glm::dvec3 surface{0.0};  // sum of the surface voxels' normals, area-weighted
  glm::dvec3 color{0.0};    // sum of their colours
  double density = 0.0;     // sum of their densities (1 each without densities)
  double temperature = 0.0; // sum of their temperatures
  void Add(const Aggregate& o) {
    count += o.count;
    normal += o.normal;
    surface += o.surface;
    color += o.color;
    density += o.density;
    temperature += o.temperature;
  }
};

// What a base voxel's sums depend on in its store's format.
struct BaseFormat {
  BaseFormat() = default;
  explicit BaseFormat(const StoreMeta& m)
      : fog(m.grid_class == GridClass::kFogVolume),
        has_density(m.has_density),
        has_normal(m.has_normal) {}
  bool fog = false, has_density = false, has_normal = false;
};

// The sums of one occupied base voxel at grid `coord` whose attributes, as
// the store returns them, are `a`. `occupied(g)` (a bool) tells whether grid
// voxel g, maybe outside the grid, is occupied. BuildLod and LodStream both
// sum their voxels here, so their pyramids agree bit for bit.
template <class OccupiedFn>
inline Aggregate VoxelSums(const VoxelAttributes& a, const glm::u64vec3& coord,
                           const BaseFormat& f, OccupiedFn&& occupied) {
  Aggregate g;
  g.count = 1;
  g.normal = glm::dvec3(a.normal);
  if (f.has_normal) {
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (std::fabs(g.normal[k]) > std::fabs(g.normal[axis])) axis = k;
    const double na = g.normal[axis];
    if (na != 0) {
      glm::i64vec3 out = glm::i64vec3(coord);
      out[axis] += na > 0 ? 1 : -1;
      if (!occupied(out)) g.surface = g.normal / std::fabs(na);
    }
  }
  g.color = glm::dvec3(a.color);
  g.temperature = double(a.temperature);
  g.density = f.has_density ? double(a.density) : (f.fog ? 1.0 : 0.0);
  return g;
}

// Bricks at most this many levels deep keep their occupancy in a bitmap
// while they are reduced; deeper ones are searched.
inline constexpr int kLodMaxBitmapDepth = 7;

// How one coarse level stores its voxels.
struct LevelFormat {
  int l = 0, depth = 0;  // the level, and its coarse bricks' depth
  bool has_normal = false, has_color = false, has_density = false, has_temperature = false;
  double cell_voxels = 1;  // base voxels in a cell, 8^l
};

// A coarse voxel made by a Cascade: its coarse brick, and the voxel in it.
struct CoarseVoxel {
  glm::u64vec3 brick{0};
  BrickVoxel voxel;
};

// A cell of level l - 1 handed up to level l with its sums: what a Cascade
// passes on beyond its last level.
struct CellUp {
  int l = 0;
  glm::u64vec3 coord{0};  // in level l - 1's grid
  Aggregate sums;
};

}  // namespace storage_internal

// A base brick's share of the pyramid: the coarse voxels of the levels whose
// cells lie inside one base brick ("local" levels), and the cells it hands
// up to the coarser ones.
struct LodReducedBrick {
  Status status;
  glm::u64vec3 brick{0};                      // LodStream: its coordinates
  std::vector<std::vector<storage_internal::CoarseVoxel>> out;  // per local level
  std::vector<storage_internal::CellUp> ups;
};

namespace storage_internal {

// A cascade of run reducers over the consecutive levels `formats` (first ..
// last): cells arrive in Morton order (Push), each level sums a run of them
// into its cell, and a finished cell becomes a coarse voxel (out(l)) and is
// handed up a level (to the next reducer, or to ups() beyond the last).
// Pure arithmetic: the same pushes give the same voxels and sums, bit for
// bit, however the work is split between cascades.
class Cascade {
 public:
  explicit Cascade(std::vector<LevelFormat> formats)
      : formats_(std::move(formats)), cells_(formats_.size()), out_(formats_.size()) {}

  int first() const { return formats_.empty() ? 1 : formats_.front().l; }
  int last() const { return first() + int(formats_.size()) - 1; }

  // A cell (or voxel) of level l - 1 at `coord` (that level's grid), with its sums.
  void Push(int l, const glm::u64vec3& coord, const Aggregate& a);
  // Emits every unfinished cell, finest level first (after the last push).
  void Flush();
  // Room for the voxels of `base_voxels` base voxels of a surface (4^-l per level).
  void Reserve(size_t base_voxels);

  // Level l's coarse voxels made so far, in Morton order; the caller may take them.
  std::vector<CoarseVoxel>& out(int l) { return out_[size_t(l - first())]; }
  // Cells handed up beyond the last level, in order.
  std::vector<CellUp>& ups() { return ups_; }
  // Moves the local levels' voxels and the cells handed up into `r`.
  void TakeInto(LodReducedBrick* r);

 private:
  struct Cell {
    bool active = false;
    glm::u64vec3 coord{0};
    Aggregate sums;
  };

  // The finished cell of level l: its coarse voxel, its sums up a level.
  void Emit(int l);

  std::vector<LevelFormat> formats_;
  std::vector<Cell> cells_;
  std::vector<std::vector<CoarseVoxel>> out_;
  std::vector<CellUp> ups_;
};

}  // namespace storage_internal
}  // namespace vox

#endif  // VOX_STORAGE_INTERNAL_LOD_REDUCE_H_

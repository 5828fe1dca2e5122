// The cascade of run reducers (storage/internal/lod_reduce.h).
#include "storage/internal/lod_reduce.h"

#include <glm/geometric.hpp>

namespace vox {
namespace storage_internal {

void Cascade::Push(int l, const glm::u64vec3& coord, const Aggregate& a) {
  if (l > last()) {
    ups_.push_back(CellUp{l, coord, a});
    return;
  }
  Cell& c = cells_[size_t(l - first())];
  const glm::u64vec3 parent = coord >> uint64_t(1);
  if (c.active && c.coord != parent) Emit(l);
  if (!c.active) {
    c.active = true;
    c.coord = parent;
    c.sums = Aggregate{};
  }
  c.sums.Add(a);
}

void Cascade::Flush() {
  for (int l = first(); l <= last(); ++l)
    if (cells_[size_t(l - first())].active) Emit(l);
}

void Cascade::Reserve(size_t base_voxels) {
  for (size_t i = 0; i < out_.size(); ++i)
    out_[i].reserve((base_voxels >> (2 * (first() + int(i)))) + 8);
}

void Cascade::TakeInto(LodReducedBrick* r) {
  Flush();
  r->out.resize(formats_.size());
  for (size_t i = 0; i < formats_.size(); ++i) r->out[i] = std::move(out_[i]);
  r->ups = std::move(ups_);
}

void Cascade::Emit(int l) {
  const LevelFormat& f = formats_[size_t(l - first())];
  Cell& c = cells_[size_t(l - first())];
  c.active = false;
  const Aggregate& a = c.sums;
  CoarseVoxel cv;
  cv.brick = c.coord >> uint64_t(f.depth);
  const glm::u64vec3 local = c.coord - (cv.brick << uint64_t(f.depth));
  BrickVoxel& v = cv.voxel;
  v.x = uint32_t(local.x);
  v.y = uint32_t(local.y);
  v.z = uint32_t(local.z);
  const double cell_voxels = f.cell_voxels;
  v.attr.coverage = float(double(a.count) / cell_voxels);
  if (f.has_normal) {
    const glm::dvec3& n = glm::length(a.surface) > 0 ? a.surface : a.normal;
    const double len = glm::length(n);
    v.attr.normal = len > 0 ? glm::vec3(n / len) : glm::vec3(0.0f);
  }
  if (f.has_color) v.attr.color = glm::vec3(a.color / double(a.count));
  if (f.has_density) v.attr.density = float(a.density / cell_voxels);
  if (f.has_temperature) v.attr.temperature = float(a.temperature / double(a.count));
  out_[size_t(l - first())].push_back(cv);
  Push(l + 1, c.coord, a);
}

}  // namespace storage_internal
}  // namespace vox

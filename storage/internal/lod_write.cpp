// The pyramid's writers (storage/internal/lod_write.h).
#include "storage/internal/lod_write.h"

#include <algorithm>
#include <cmath>

#include <glm/gtc/matrix_transform.hpp>

namespace vox {
namespace storage_internal {

uint64_t LevelStoreId(uint64_t base_id, int level) {
  uint64_t z = base_id + 0x9E3779B97F4A7C15ull * uint64_t(level + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return z != 0 ? z : 1;
}

StoreMeta CoarseMeta(const StoreMeta& base, uint64_t base_id, int l, int depth) {
  StoreMeta m = base;
  m.levels = base.levels - l;
  m.brick_level = m.levels - depth;
  m.origin = glm::i64vec3(0);
  const double s = std::ldexp(1.0, l);
  const glm::dvec3 shift = glm::dvec3(base.origin) + glm::dvec3(0.5 * s - 0.5);
  m.index_to_world = base.index_to_world * glm::translate(glm::dmat4(1.0), shift) *
                     glm::scale(glm::dmat4(1.0), glm::dvec3(s));
  m.voxel_size = base.voxel_size * s;
  m.has_coverage = true;
  // Fog: the mean density over a cell (a store without densities counts 1 per voxel).
  m.has_density = base.has_density || base.grid_class == GridClass::kFogVolume;
  m.lod_level = l;
  m.lod_base_store_id = base_id;
  m.lod_base_levels = base.levels;
  m.build_options = "level of detail " + std::to_string(l) + " of: " + base.build_options;
  return m;
}

Status LevelWriters::Init(const StoreMeta& base, uint64_t base_id, const std::string& dir,
                          const std::vector<LevelFormat>& formats, const LodBuildOptions& o) {
  levels_.resize(formats.size());
  for (size_t i = 0; i < formats.size(); ++i) {
    const int l = formats[i].l;
    WriteOptions wo;
    wo.zstd_level = o.zstd_level;
    wo.normal_bits = o.normal_bits;
    wo.store_id = LevelStoreId(base_id, l);
    VOX_ASSIGN_OR_RETURN(levels_[i].writer,
                         StoreWriter::Create(dir + "/" + std::to_string(l),
                                             CoarseMeta(base, base_id, l, formats[i].depth), wo));
  }
  return OkStatus();
}

Status LevelWriters::Add(int l, std::vector<CoarseVoxel>& voxels) {
  Level& lv = levels_[size_t(l - 1)];
  for (CoarseVoxel& cv : voxels) {
    if (lv.brick_active && cv.brick != lv.brick) VOX_RETURN_IF_ERROR(FlushBrick(lv));
    lv.brick_active = true;
    lv.brick = cv.brick;
    lv.voxels.push_back(cv.voxel);
    ++lv.voxel_count;
  }
  voxels.clear();
  return OkStatus();
}

Status LevelWriters::Finish(LodBuildStats* stats) {
  for (Level& lv : levels_) {
    VOX_RETURN_IF_ERROR(FlushBrick(lv));
    VOX_RETURN_IF_ERROR(lv.writer->Finish());
    stats->voxels.push_back(lv.voxel_count);
    stats->bricks.push_back(lv.brick_count);
  }
  stats->levels = int(levels_.size());
  return OkStatus();
}

Status LevelWriters::FlushBrick(Level& lv) {
  if (!lv.brick_active || lv.voxels.empty()) return OkStatus();
  ++lv.brick_count;
  Status s = lv.writer->AddBrick(lv.brick, std::move(lv.voxels));
  lv.voxels = {};
  lv.brick_active = false;
  return s;
}

Status PyramidWriter::Init(const StoreMeta& bm, uint64_t base_id, const std::string& dir,
                           const LodBuildOptions& o) {
  // Levels 1 .. D have their cells inside one base brick (local), the coarser ones not.
  const int max_level = LodMaxLevel(bm.levels);
  const int local_levels = std::min(bm.levels - bm.brick_level, max_level);
  std::vector<LevelFormat> all;
  for (int l = 1; l <= max_level; ++l) {
    LevelFormat f;
    f.l = l;
    f.depth = LodBrickDepth(bm.levels, bm.levels - bm.brick_level, l);
    f.cell_voxels = std::ldexp(1.0, 3 * l);
    const StoreMeta m = CoarseMeta(bm, base_id, l, f.depth);
    f.has_normal = m.has_normal;
    f.has_color = m.has_color;
    f.has_density = m.has_density;
    f.has_temperature = m.has_temperature;
    (l <= local_levels ? local_ : upper_).push_back(f);
    all.push_back(f);
  }
  serial_ = Cascade(upper_);
  return writers_.Init(bm, base_id, dir, all, o);
}

Status PyramidWriter::Take(LodReducedBrick& r) {
  VOX_RETURN_IF_ERROR(r.status);
  for (size_t i = 0; i < local_.size(); ++i)
    VOX_RETURN_IF_ERROR(writers_.Add(local_[i].l, r.out[i]));
  for (const CellUp& up : r.ups) serial_.Push(up.l, up.coord, up.sums);
  return Drain();
}

Status PyramidWriter::Finish(LodBuildStats* stats) {
  serial_.Flush();
  VOX_RETURN_IF_ERROR(Drain());
  return writers_.Finish(stats);
}

Status PyramidWriter::Drain() {
  for (const LevelFormat& f : upper_) VOX_RETURN_IF_ERROR(writers_.Add(f.l, serial_.out(f.l)));
  serial_.ups().clear();  // beyond the coarsest level
  return OkStatus();
}

}  // namespace storage_internal
}  // namespace vox

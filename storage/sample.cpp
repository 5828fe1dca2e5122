#include "storage/sample.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include <glm/mat4x4.hpp>

#include "core/octree.h"
#include "core/ray.h"
#include "storage/lod.h"

namespace vox {

namespace {

bool Has(ValueAttr a, const StoreMeta& m) {
  switch (a) {
    case ValueAttr::kOccupancy: return true;
    case ValueAttr::kDensity: return m.has_density;
    case ValueAttr::kColor: return m.has_color;
    case ValueAttr::kNormal: return m.has_normal;
    case ValueAttr::kCoverage: return m.has_coverage;
  }
  return false;
}

constexpr ValueAttr kAllAttrs[] = {ValueAttr::kOccupancy, ValueAttr::kDensity, ValueAttr::kColor,
                                   ValueAttr::kNormal, ValueAttr::kCoverage};

// Writes attribute `a` of an occupied voxel to out[0 .. components).
void Put(ValueAttr a, const VoxelAttributes& v, float* out) {
  switch (a) {
    case ValueAttr::kOccupancy: out[0] = 1.0f; break;
    case ValueAttr::kDensity: out[0] = v.density; break;
    case ValueAttr::kCoverage: out[0] = v.coverage; break;
    case ValueAttr::kColor: for (int c = 0; c < 3; ++c) out[c] = v.color[c]; break;
    case ValueAttr::kNormal: for (int c = 0; c < 3; ++c) out[c] = v.normal[c]; break;
  }
}

}  // namespace

StatusOr<ValueAttr> ParseValueAttr(const std::string& name, const StoreMeta& meta) {
  std::string have;
  for (ValueAttr a : kAllAttrs) {
    if (!Has(a, meta)) continue;
    if (name == ValueAttrName(a)) return a;
    have += std::string(have.empty() ? "" : ", ") + ValueAttrName(a);
  }
  return InvalidArgumentError("attribute '" + name + "': this store keeps " + have);
}

const char* ValueAttrName(ValueAttr a) {
  switch (a) {
    case ValueAttr::kOccupancy: return "occupancy";
    case ValueAttr::kDensity: return "density";
    case ValueAttr::kColor: return "color";
    case ValueAttr::kNormal: return "normal";
    case ValueAttr::kCoverage: return "coverage";
  }
  return "?";
}

int ValueAttrComponents(ValueAttr a) {
  return a == ValueAttr::kColor || a == ValueAttr::kNormal ? 3 : 1;
}

ValueAttr DefaultValueAttr(const StoreMeta& meta) {
  return meta.has_density ? ValueAttr::kDensity : ValueAttr::kOccupancy;
}

// A walk of the volume's octree over a box of grid coordinates [lo, hi),
// visiting each occupied voxel in it with its attributes; bricks are fetched
// one at a time through the volume's cache and released when left.
struct StoreValues::Walk {
  Volume* volume;
  OctreeView view;
  glm::i64vec3 lo, hi;
  std::function<void(const glm::i64vec3&, const VoxelAttributes&)> visit;

  Status Cells(const CompactCell* pool, uint32_t cell, int depth, const glm::i64vec3& base,
               uint32_t brick, const void* data) {
    const int64_t half = int64_t(1) << (view.levels - depth - 1);
    for (unsigned digit = 0; digit < 8; ++digit) {
      const glm::i64vec3 c = base + glm::i64vec3(digit & 1, (digit >> 1) & 1, (digit >> 2) & 1) * half;
      if (c.x >= hi.x || c.y >= hi.y || c.z >= hi.z || c.x + half <= lo.x || c.y + half <= lo.y ||
          c.z + half <= lo.z)
        continue;
      const ChildRef ref = ChildOf(pool[cell], digit, depth, view);
      switch (ref.kind) {
        case ChildRef::kEmpty: break;
        case ChildRef::kCell: VOX_RETURN_IF_ERROR(Cells(pool, ref.index, depth + 1, c, brick, data)); break;
        case ChildRef::kBrick: {
          if (view.bricks == nullptr) return CorruptionError("a brick reference without bricks");
          VOX_ASSIGN_OR_RETURN(BrickView b, view.bricks->FetchBrick(ref.index));
          VOX_RETURN_IF_ERROR(Cells(b.cells, 0, depth + 1, c, ref.index, b.data));
          break;
        }
        case ChildRef::kPayload: {
          Hit h;
          h.brick = brick;
          h.payload = ref.index;
          h.brick_data = data;
          VOX_ASSIGN_OR_RETURN(VoxelAttributes a, volume->HitAttributes(h));
          visit(c, a);
          break;
        }
      }
    }
    return OkStatus();
  }

  Status Run() {
    const int64_t n = int64_t(1) << view.levels;
    lo = glm::max(lo, glm::i64vec3(0));
    hi = glm::min(hi, glm::i64vec3(n));
    if (view.top_cells == 0 || lo.x >= hi.x || lo.y >= hi.y || lo.z >= hi.z) return OkStatus();
    return Cells(view.top, 0, 0, glm::i64vec3(0), kNoBrick, nullptr);
  }
};

StatusOr<std::unique_ptr<StoreValues>> StoreValues::Open(const std::string& dir, int level,
                                                         uint64_t cache_bytes) {
  if (level < 0) return InvalidArgumentError("level " + std::to_string(level) + " is negative");
  std::unique_ptr<StoreValues> v(new StoreValues());
  OpenOptions oo;
  oo.cache_bytes = cache_bytes;
  VOX_ASSIGN_OR_RETURN(v->base_, Store::Open(dir, oo));
  v->volume_ = v->base_.get();
  v->level_ = level;
  if (level > 0) {
    VOX_ASSIGN_OR_RETURN(v->pyramid_, LodPyramid::Open(dir, *v->base_, oo));
    if (level > v->pyramid_->max_level())
      return InvalidArgumentError("level " + std::to_string(level) + ": store '" + dir +
                                  "' has levels 0 to " + std::to_string(v->pyramid_->max_level()));
    v->volume_ = v->pyramid_->level(level);
  }
  return v;
}

StoreValues::~StoreValues() = default;

const StoreMeta& StoreValues::meta() const { return base_->meta(); }

void StoreValues::OccupiedBox(glm::i64vec3* lo, glm::i64vec3* hi) const {
  const StoreMeta& m = meta();
  const glm::i64vec3 shift = m.origin >> int64_t(level_);
  if (m.voxel_count == 0) {
    *lo = *hi = shift;
    return;
  }
  *lo = ((m.bbox_min - m.origin) >> int64_t(level_)) + shift;
  *hi = ((m.bbox_max - m.origin) >> int64_t(level_)) + shift + int64_t(1);
}

glm::dvec3 StoreValues::WorldToIndex(const glm::dvec3& world) const {
  return glm::dvec3(glm::inverse(meta().index_to_world) * glm::dvec4(world, 1.0)) + 0.5;
}

uint64_t StoreValues::ReadBytes(const glm::i64vec3& lo, const glm::i64vec3& hi, ValueAttr attr) {
  const glm::i64vec3 n = glm::max(hi - lo, glm::i64vec3(0));
  const double bytes = double(n.x) * double(n.y) * double(n.z) * ValueAttrComponents(attr) * sizeof(float);
  return bytes >= 1.8e19 ? std::numeric_limits<uint64_t>::max() : uint64_t(bytes);
}

Status StoreValues::Read(const glm::i64vec3& lo, const glm::i64vec3& hi, ValueAttr attr, float* out) {
  if (hi.x < lo.x || hi.y < lo.y || hi.z < lo.z)
    return InvalidArgumentError("the box's upper corner is below its lower corner");
  if (!Has(attr, volume_->meta()))
    return InvalidArgumentError(std::string("the store keeps no ") + ValueAttrName(attr));
  const int comps = ValueAttrComponents(attr);
  const glm::i64vec3 n = hi - lo;
  std::fill(out, out + size_t(n.x) * size_t(n.y) * size_t(n.z) * comps, 0.0f);
  const glm::i64vec3 shift = meta().origin >> int64_t(level_);
  Walk w{volume_, volume_->view(), lo - shift, hi - shift, nullptr};
  w.visit = [&](const glm::i64vec3& g, const VoxelAttributes& a) {
    const glm::i64vec3 d = g + shift - lo;
    Put(attr, a, out + ((size_t(d.x) * size_t(n.y) + size_t(d.y)) * size_t(n.z) + size_t(d.z)) * comps);
  };
  return w.Run();
}

StatusOr<Samples> StoreValues::Sample(std::span<const glm::dvec3> points, SampleMode mode) {
  const StoreMeta& lm = volume_->meta();
  const size_t n = points.size();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Samples s;
  s.inside.assign(n, 0);
  s.occupancy.assign(n, nan);
  if (lm.has_density) s.density.assign(n, nan);
  if (lm.has_coverage) s.coverage.assign(n, nan);
  if (lm.has_color) s.color.assign(3 * n, nan);
  if (lm.has_normal) s.normal.assign(3 * n, nan);
  glm::i64vec3 blo, bhi;
  OccupiedBox(&blo, &bhi);
  const glm::dvec3 origin(meta().origin);
  const glm::dvec3 shift(meta().origin >> int64_t(level_));
  const double scale = std::ldexp(1.0, -level_);
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec3 p = (points[i] - origin) * scale + shift;  // this level's index space
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      return InvalidArgumentError("point " + std::to_string(i) + " is not finite");
    const glm::i64vec3 cell(glm::floor(p));
    if (glm::any(glm::lessThan(cell, blo)) || glm::any(glm::greaterThanEqual(cell, bhi))) continue;
    s.inside[i] = 1;
    // The cells to weigh: the one holding p, or the 8 around p - 0.5.
    const glm::dvec3 q = p - 0.5;
    const glm::i64vec3 c0 = mode == SampleMode::kNearest ? cell : glm::i64vec3(glm::floor(q));
    const glm::dvec3 f = q - glm::floor(q);
    float occ = 0, den = 0, cov = 0;
    glm::vec3 col(0.0f), nor(0.0f);
    const int corners = mode == SampleMode::kNearest ? 1 : 8;
    for (int k = 0; k < corners; ++k) {
      const glm::i64vec3 d(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      const float w = mode == SampleMode::kNearest
                           ? 1.0f
                           : float((d.x ? f.x : 1 - f.x) * (d.y ? f.y : 1 - f.y) * (d.z ? f.z : 1 - f.z));
      bool found = false;
      VoxelAttributes a;
      const glm::i64vec3 g = c0 + d - glm::i64vec3(shift);
      Walk walk{volume_, volume_->view(), g, g + int64_t(1), [&](const glm::i64vec3&, const VoxelAttributes& v) {
                  found = true;
                  a = v;
                }};
      VOX_RETURN_IF_ERROR(walk.Run());
      if (!found) continue;
      occ += w;
      den += w * a.density;
      cov += w * a.coverage;
      col += w * a.color;
      nor += w * a.normal;
    }
    s.occupancy[i] = occ;
    if (lm.has_density) s.density[i] = den;
    if (lm.has_coverage) s.coverage[i] = cov;
    for (int c = 0; c < 3; ++c) {
      if (lm.has_color) s.color[3 * i + c] = col[c];
      if (lm.has_normal) s.normal[3 * i + c] = nor[c];
    }
  }
  return s;
}

}  // namespace vox

// The light reaching points in fog, kept on a lattice: fog.cpp evaluates the
// light (the transmittance rays to the lights) at the lattice points around
// a sample and interpolates their logarithms trilinearly, so neighbouring
// pixels and samples share transmittance rays. A lattice point's value
// depends on the point alone, never on which pixel asked first, so tiles,
// threads and Slurm parts give the same image bit for bit. Private to
// render/.
//
// Thread safety: a FogLightCache belongs to one thread (Renderer::ThreadState).
#ifndef VOX_RENDER_INTERNAL_FOG_LIGHT_H_
#define VOX_RENDER_INTERNAL_FOG_LIGHT_H_

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <unordered_map>

namespace vox::render_internal {

// A lattice of spacing 2^level voxels: point i lies at (i + 1/2) 2^level in
// grid coordinates (cell centres of the pyramid's level `level`).
struct LatticePoint {
  int64_t x, y, z;
  int level;
  bool operator==(const LatticePoint& o) const {
    return x == o.x && y == o.y && z == o.z && level == o.level;
  }
};

struct LatticePointHash {
  size_t operator()(const LatticePoint& p) const {
    uint64_t h = uint64_t(p.x) * 0x9E3779B97F4A7C15ull;
    h ^= uint64_t(p.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= uint64_t(p.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    h ^= uint64_t(p.level) * 0x27D4EB2F165667C5ull;
    return size_t(h ^ (h >> 29));
  }
};

class FogLightCache {
 public:
  // Points kept at most; the cache starts again when full (its values do not
  // depend on what it held, so nothing but time changes).
  static constexpr size_t kMaxPoints = size_t(1) << 16;
  // Bytes it holds at most (entries and buckets), for the memory budget.
  static constexpr size_t kMaxBytes = kMaxPoints * 96;

  void Clear() {
    points_.clear();
    block_valid_ = false;
  }

  // The log-light (per channel; -inf where no light arrives) at the eight
  // lattice points of the block whose lowest corner is `i0`, computing
  // missing ones with `light(const glm::dvec3& p_grid, glm::dvec3* log_light)
  // -> bool` (false: the frame failed; nothing is kept). Returns false on
  // failure.
  template <class Light>
  bool Block(int level, const glm::i64vec3& i0, Light&& light, glm::dvec3 out[8]) {
    if (block_valid_ && block_level_ == level && block_i0_ == i0) {
      for (int c = 0; c < 8; ++c) out[c] = block_[c];
      return true;
    }
    if (points_.size() + 8 > kMaxPoints) points_.clear();
    const double s = std::ldexp(1.0, level);
    for (int c = 0; c < 8; ++c) {
      const LatticePoint p{i0.x + (c & 1), i0.y + ((c >> 1) & 1), i0.z + ((c >> 2) & 1), level};
      auto it = points_.find(p);
      if (it == points_.end()) {
        glm::dvec3 v;
        if (!light(glm::dvec3((double(p.x) + 0.5) * s, (double(p.y) + 0.5) * s,
                              (double(p.z) + 0.5) * s),
                   &v))
          return false;
        it = points_.emplace(p, v).first;
      }
      out[c] = it->second;
    }
    for (int c = 0; c < 8; ++c) block_[c] = out[c];
    block_valid_ = true;
    block_level_ = level;
    block_i0_ = i0;
    return true;
  }

 private:
  std::unordered_map<LatticePoint, glm::dvec3, LatticePointHash> points_;
  bool block_valid_ = false;
  int block_level_ = 0;
  glm::i64vec3 block_i0_{0};
  glm::dvec3 block_[8];
};

}  // namespace vox::render_internal

#endif  // VOX_RENDER_INTERNAL_FOG_LIGHT_H_

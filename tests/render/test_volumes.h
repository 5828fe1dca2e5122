// Small generated volumes for the render tests: voxels chosen by an implicit
// function, normals from its analytic gradient. Grid voxel g covers world
// [g, g+1)^3 scaled by `voxel` (index_to_world = scale(voxel) * translate(0.5)).
#ifndef VOX_TESTS_RENDER_TEST_VOLUMES_H_
#define VOX_TESTS_RENDER_TEST_VOLUMES_H_

#include <functional>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <vector>

#include "render/grid_transform.h"

namespace vox::testing {

struct Part {
  // World-space implicit test at a voxel centre, and the outward normal there.
  std::function<bool(const glm::dvec3&)> inside;
  std::function<glm::dvec3(const glm::dvec3&)> normal;  // may be null: no normal stored
  glm::vec3 color{1.0f};
  float density = 1.0f;
};

inline StoreMeta TestMeta(int levels, GridClass cls, double voxel = 1.0) {
  StoreMeta m;
  m.grid_name = "test";
  m.grid_class = cls;
  m.levels = levels;
  m.brick_level = levels > 3 ? levels - 3 : levels;
  m.origin = glm::i64vec3(0);
  m.index_to_world = glm::scale(glm::dmat4(1.0), glm::dvec3(voxel)) *
                     glm::translate(glm::dmat4(1.0), glm::dvec3(0.5));
  m.voxel_size = voxel;
  m.has_normal = true;
  m.has_density = cls == GridClass::kFogVolume;
  return m;
}

inline std::unique_ptr<MemoryVolume> MakeVolume(const StoreMeta& meta,
                                                const std::vector<Part>& parts,
                                                bool has_color = false) {
  StoreMeta m = meta;
  m.has_color = has_color;
  const int64_t n = int64_t(1) << m.levels;
  std::vector<MemoryVoxel> voxels;
  for (int64_t z = 0; z < n; ++z)
    for (int64_t y = 0; y < n; ++y)
      for (int64_t x = 0; x < n; ++x) {
        glm::dvec3 c = (glm::dvec3(x, y, z) + 0.5) * m.voxel_size;
        for (const Part& p : parts) {
          if (!p.inside(c)) continue;
          MemoryVoxel v;
          v.x = uint64_t(x);
          v.y = uint64_t(y);
          v.z = uint64_t(z);
          if (p.normal) v.attr.normal = glm::vec3(glm::normalize(p.normal(c)));
          v.attr.color = p.color;
          v.attr.density = p.density;
          voxels.push_back(v);
          break;
        }
      }
  auto vol = MemoryVolume::Create(m, std::move(voxels));
  return vol.ok() ? std::move(vol).value() : nullptr;
}

inline Part Sphere(glm::dvec3 c, double r, glm::vec3 color = glm::vec3(1.0f)) {
  Part p;
  p.inside = [=](const glm::dvec3& q) { return glm::length(q - c) <= r; };
  p.normal = [=](const glm::dvec3& q) { return q - c; };
  p.color = color;
  return p;
}

// Axis-aligned world box [lo, hi] with the normal of the nearest face.
inline Part Box(glm::dvec3 lo, glm::dvec3 hi, glm::vec3 color = glm::vec3(1.0f),
                bool normals = true) {
  Part p;
  p.inside = [=](const glm::dvec3& q) {
    return q.x >= lo.x && q.y >= lo.y && q.z >= lo.z && q.x <= hi.x && q.y <= hi.y && q.z <= hi.z;
  };
  if (normals)
    p.normal = [=](const glm::dvec3& q) {
      double best = 1e300;
      glm::dvec3 n(0.0);
      for (int a = 0; a < 3; ++a) {
        if (q[a] - lo[a] < best) {
          best = q[a] - lo[a];
          n = glm::dvec3(0.0);
          n[a] = -1;
        }
        if (hi[a] - q[a] < best) {
          best = hi[a] - q[a];
          n = glm::dvec3(0.0);
          n[a] = 1;
        }
      }
      return n;
    };
  p.color = color;
  return p;
}

}  // namespace vox::testing

#endif  // VOX_TESTS_RENDER_TEST_VOLUMES_H_

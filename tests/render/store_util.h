// Writes generated voxels to a real store with StoreWriter, for tests that
// run vox-render end to end.
#ifndef VOX_TESTS_RENDER_STORE_UTIL_H_
#define VOX_TESTS_RENDER_STORE_UTIL_H_

#include <algorithm>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "render/grid_transform.h"
#include "storage/store.h"
#include "storage/store_writer.h"
#include "tests/render/test_volumes.h"

namespace vox::testing {

// The voxels of an n^3 grid whose distance from `centre` (in grid
// coordinates, from the voxel's corner) lies in [r_in, r_out], with normals
// pointing away from the centre: a sphere shell for end-to-end tests.
inline std::vector<MemoryVoxel> ShellVoxels(int n, glm::dvec3 centre, double r_in, double r_out) {
  std::vector<MemoryVoxel> voxels;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        glm::dvec3 d = glm::dvec3(x, y, z) - centre;
        double r = glm::length(d);
        if (r > r_out || r < r_in) continue;
        MemoryVoxel v;
        v.x = uint64_t(x);
        v.y = uint64_t(y);
        v.z = uint64_t(z);
        v.attr.normal = glm::vec3(d / std::max(r, 1e-9));
        voxels.push_back(v);
      }
  return voxels;
}

// `meta` as for MemoryVolume; the voxels are grid coordinates.
inline Status WriteStore(const std::string& dir, StoreMeta meta,
                         const std::vector<MemoryVoxel>& voxels) {
  const int sub = meta.levels - meta.brick_level;
  std::map<std::tuple<uint64_t, uint64_t, uint64_t>, std::vector<BrickVoxel>> bricks;
  const uint64_t mask = (uint64_t(1) << sub) - 1;
  for (const MemoryVoxel& v : voxels) {
    BrickVoxel b;
    b.x = uint32_t(v.x & mask);
    b.y = uint32_t(v.y & mask);
    b.z = uint32_t(v.z & mask);
    b.attr = v.attr;
    bricks[{v.x >> sub, v.y >> sub, v.z >> sub}].push_back(b);
  }
  WriteOptions wo;
  wo.force = true;
  VOX_ASSIGN_OR_RETURN(auto writer, StoreWriter::Create(dir, meta, wo));
  for (auto& [coord, list] : bricks)
    VOX_RETURN_IF_ERROR(writer->AddBrick(
        {std::get<0>(coord), std::get<1>(coord), std::get<2>(coord)}, std::move(list)));
  return writer->Finish();
}

// The tools tests' store: a 64^3 level set (bricks of 8^3, voxels of 0.25)
// holding a shell of radius 17..20 voxels around index (0,0,0), world radius 5.
inline Status WriteSphereShellStore(const std::string& dir) {
  StoreMeta meta = TestMeta(6, GridClass::kLevelSet, 0.25);
  meta.brick_level = 3;
  meta.origin = {-32, -32, -32};
  meta.index_to_world = glm::scale(glm::dmat4(1.0), glm::dvec3(0.25));
  meta.source_file = "generated";
  meta.grid_name = "sphere";
  return WriteStore(dir, meta, ShellVoxels(64, glm::dvec3(32), 17, 20));
}

}  // namespace vox::testing

#endif  // VOX_TESTS_RENDER_STORE_UTIL_H_

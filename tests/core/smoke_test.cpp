#include <gtest/gtest.h>

#include "core/core.h"
#include "core/shapes.h"

namespace vox {
namespace {

TEST(Smoke, SphereHitFromOutside) {
  auto vol = GenerateShape("sphere:64");
  ASSERT_TRUE(vol.ok());
  for (int bl : {6, 3}) {
    auto tree = MemoryOctree::Build(vol->voxels, vol->levels, bl);
    ASSERT_TRUE(tree.ok()) << tree.status().ToString();
    for (int n1 : {6, 3, 2}) {
      auto tr = Tracer<>::Create((*tree)->view(), n1);
      ASSERT_TRUE(tr.ok()) << tr.status().ToString();
      Ray r{{32.3, 32.7, -10}, {0, 0, 1}};
      TraceCounters c;
      auto h = tr->FirstHit(r, &c);
      ASSERT_TRUE(h.ok());
      ASSERT_TRUE(h->has_value());
      EXPECT_EQ((*h)->voxel.x, 32);
      EXPECT_EQ((*h)->voxel.y, 32);
      EXPECT_EQ((*h)->voxel.z, 6);  // centre 32, r = 25.6 -> first voxel with centre inside: z=6
    }
  }
}

}  // namespace
}  // namespace vox

// Colour sampling from a vec3 grid of the same file. See color.h.
#include "ingest/internal/color.h"

#include "ingest/internal/leaf_values.h"

namespace vox::ingest_internal {
namespace {

using openvdb::Coord;

template <class CGridT>
class TypedColorSource : public ColorSource {
 public:
  TypedColorSource(typename CGridT::Ptr grid, const openvdb::math::Transform& main)
      : grid_(std::move(grid)), main_(main), same_(grid_->transform() == main) {}

  std::unique_ptr<ColorReader> NewReader() override {
    return std::make_unique<Reader>(*grid_, main_, same_);
  }

 private:
  class Reader : public ColorReader {
   public:
    Reader(const CGridT& grid, const openvdb::math::Transform& main, bool same)
        : grid_(grid), main_(main), same_(same), values_(grid) {}
    glm::vec3 At(const Coord& ijk) override {
      openvdb::Vec3d v;
      if (same_) {
        v = openvdb::Vec3d(values_.Value(ijk));
      } else {
        // Trilinear, as openvdb::tools::BoxSampler.
        openvdb::Vec3d p = grid_.transform().worldToIndex(main_.indexToWorld(ijk));
        Coord i0 = Coord::floor(p);
        openvdb::Vec3d u = p - i0.asVec3d();
        openvdb::Vec3d c[2][2][2];
        for (int dx = 0; dx < 2; ++dx)
          for (int dy = 0; dy < 2; ++dy)
            for (int dz = 0; dz < 2; ++dz)
              c[dx][dy][dz] = openvdb::Vec3d(values_.Value(i0.offsetBy(dx, dy, dz)));
        auto lerp = [](const openvdb::Vec3d& a, const openvdb::Vec3d& b, double t) {
          return a + (b - a) * t;
        };
        openvdb::Vec3d x00 = lerp(c[0][0][0], c[0][0][1], u[2]);
        openvdb::Vec3d x01 = lerp(c[0][1][0], c[0][1][1], u[2]);
        openvdb::Vec3d x10 = lerp(c[1][0][0], c[1][0][1], u[2]);
        openvdb::Vec3d x11 = lerp(c[1][1][0], c[1][1][1], u[2]);
        v = lerp(lerp(x00, x01, u[1]), lerp(x10, x11, u[1]), u[0]);
      }
      if (++reads_ % 4096 == 0) values_.Clear();  // bound the private leaf cache
      return glm::vec3(float(v[0]), float(v[1]), float(v[2]));
    }

   private:
    const CGridT& grid_;
    const openvdb::math::Transform& main_;
    bool same_;
    PrivateReader<CGridT> values_;
    uint64_t reads_ = 0;
  };

  typename CGridT::Ptr grid_;
  const openvdb::math::Transform& main_;
  bool same_;
};

}  // namespace

std::unique_ptr<ColorSource> NewColorSource(openvdb::GridBase::Ptr grid,
                                            const openvdb::math::Transform& main) {
  if (auto g = openvdb::gridPtrCast<openvdb::Vec3fGrid>(grid))
    return std::make_unique<TypedColorSource<openvdb::Vec3fGrid>>(g, main);
  if (auto g = openvdb::gridPtrCast<openvdb::Vec3dGrid>(grid))
    return std::make_unique<TypedColorSource<openvdb::Vec3dGrid>>(g, main);
  return nullptr;
}

std::unique_ptr<ColorSource> NewScalarSource(openvdb::GridBase::Ptr grid,
                                             const openvdb::math::Transform& main) {
  if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(grid))
    return std::make_unique<TypedColorSource<openvdb::FloatGrid>>(g, main);
  if (auto g = openvdb::gridPtrCast<openvdb::DoubleGrid>(grid))
    return std::make_unique<TypedColorSource<openvdb::DoubleGrid>>(g, main);
  return nullptr;
}

}  // namespace vox::ingest_internal

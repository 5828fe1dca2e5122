// vox::StoreValues: the values a store keeps, read back at points, in boxes
// and in slices, out of core through the store's brick cache (the bricks a
// read touches are fetched one at a time; the cache keeps its budget).
//
// Coordinates (docs/usage.md, "Spaces"): voxel (i, j, k) is OpenVDB's
// Coord(i, j, k); an index-space *point* P lies in voxel floor(P), so
// OpenVDB's index point q is P = q + 0.5, and a world point W is
// P = inverse(index_to_world) W + 0.5. Level l > 0 reads the store's
// level-of-detail pyramid (storage/lod.h): there cell c covers the 2^l
// voxels per axis whose (ijk - origin) >> l equals c - (origin >> l), so
// with an origin divisible by 2^l, cell c is voxels c * 2^l + [0, 2^l). A
// point P of the base's index space is (P - origin) / 2^l + (origin >> l)
// in the level's cells; boxes at level l are given in its cells.
//
// Values: the attribute where the voxel (cell) is occupied, 0 elsewhere.
//
// Thread safety: a StoreValues is used by one thread at a time.
#ifndef VOX_STORAGE_SAMPLE_H_
#define VOX_STORAGE_SAMPLE_H_

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "core/util/status.h"
#include "storage/meta.h"
#include "storage/store.h"

namespace vox {

class LodPyramid;

enum class ValueAttr { kOccupancy, kDensity, kColor, kNormal, kCoverage };
// "occupancy", "density", "color", "normal", "coverage"; an attribute the
// store does not keep is refused, naming those it has.
StatusOr<ValueAttr> ParseValueAttr(const std::string& name, const StoreMeta& meta);
const char* ValueAttrName(ValueAttr a);
int ValueAttrComponents(ValueAttr a);  // 3 for colour and normal, else 1
// The density of a fog store, the occupancy otherwise.
ValueAttr DefaultValueAttr(const StoreMeta& meta);

enum class SampleMode { kNearest, kTrilinear };

// Values at points: per point, `inside` is 0 where the point lies outside
// the occupied box (then every value is NaN), else 1. Nearest: the voxel
// holding the point. Trilinear: OpenVDB's BoxSampler convention, voxel
// centres at ijk + 0.5 in vox's index space, each of the 8 neighbours
// weighted, unoccupied ones counting 0. Arrays the store has no attribute
// for are empty; colour and normal are 3 floats per point.
struct Samples {
  std::vector<uint8_t> inside;
  std::vector<float> occupancy, density, coverage, color, normal;
};

class StoreValues {
 public:
  // Opens `dir` (and, for level > 0, its pyramid) with a brick cache of
  // `cache_bytes` per store.
  static StatusOr<std::unique_ptr<StoreValues>> Open(const std::string& dir, int level,
                                                     uint64_t cache_bytes);
  ~StoreValues();
  const StoreMeta& meta() const;  // the base store's
  int level() const { return level_; }
  // The occupied box at this level, in its cells: [lo, hi) per axis (empty: lo == hi).
  void OccupiedBox(glm::i64vec3* lo, glm::i64vec3* hi) const;
  // OpenVDB's world point -> vox index point (base level).
  glm::dvec3 WorldToIndex(const glm::dvec3& world) const;
  // Values at index points of the base level (see the header comment).
  StatusOr<Samples> Sample(std::span<const glm::dvec3> index_points, SampleMode mode);
  // Fills `out` (C order: x slowest, then y, z, then the attribute's
  // components) with the box [lo, hi) of this level's cells.
  Status Read(const glm::i64vec3& lo, const glm::i64vec3& hi, ValueAttr attr, float* out);
  // Bytes Read writes for the box.
  static uint64_t ReadBytes(const glm::i64vec3& lo, const glm::i64vec3& hi, ValueAttr attr);

 private:
  StoreValues() = default;
  struct Walk;
  std::unique_ptr<Store> base_;
  std::unique_ptr<LodPyramid> pyramid_;
  Volume* volume_ = nullptr;  // the level read
  int level_ = 0;
};

}  // namespace vox

#endif  // VOX_STORAGE_SAMPLE_H_

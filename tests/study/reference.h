// vox::testing::Reference: an exact first-hit oracle for the tracer tests and
// the accuracy study (vox-study), written independently of core's tracer, Ray
// helpers and octree builder. It shares only the Ray/Hit value types (for the
// acceptance check).
//
// Semantics. A ray is origin + t * dir, t >= 0, with the six doubles taken as
// exact rationals. Voxel v is the half-open cube [v, v+1)^3; its
// closed cube is [v, v+1]^3.
//   - The ray *meets* v when it meets the half-open cube in a segment of
//     positive length. For an axis whose direction is nonzero this is the same
//     as meeting the closed cube in positive length; for an axis whose
//     direction is exactly zero (+0 or -0) the ray's coordinate o_a must lie
//     in [v_a, v_a + 1). So a ray lying in the face plane y = 5 meets row 5,
//     not row 4 (which it only touches).
//   - The ray *touches* v when it meets the closed cube at all (a point is
//     enough). The entry parameter of either is the smallest such t.
//   - The first hit is the occupied voxel the ray meets with the smallest
//     entry parameter. It is *ambiguous* when another occupied voxel's closed
//     cube is touched at a parameter <= that entry (edges, corners, face
//     planes, ties).
//
// Exactness. Ray parameters are (plane - o_a) / dir_a for integer planes; they
// are compared with a long double filter (64-bit significand, exponent range
// wide enough for every double quotient, so no overflow or underflow), and
// with GMP rationals whenever the filter's error bound cannot decide.
//
// Pruning. Per-level hash tables of occupied cells (child masks), children
// visited in entry order and cut at the best entry found so far.
//
// Thread safety: a Reference is immutable after construction; its queries are
// const and may run concurrently.
#ifndef VOX_TESTS_STUDY_REFERENCE_H_
#define VOX_TESTS_STUDY_REFERENCE_H_

#include <gmpxx.h>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/ray.h"

namespace vox::testing {

using Voxel = std::array<int64_t, 3>;

// A ray taken exactly: the doubles, their long double copies and rationals.
class ExactRay {
 public:
  explicit ExactRay(const Ray& ray);
  const Ray& ray() const { return ray_; }

  // A ray parameter: 0, or where the ray crosses the plane x_axis = plane.
  struct T {
    int axis = -1;        // -1: t = 0
    int64_t plane = 0;
    long double approx = 0;  // relative error <= 2^-63; exactly 0 iff t == 0
  };
  T Zero() const { return T{}; }
  T Plane(int axis, int64_t plane) const;
  // Sign of a - b, exactly.
  int Compare(const T& a, const T& b) const;
  mpq_class Exact(const T& t) const;

  long double o(int a) const { return ol_[a]; }
  long double d(int a) const { return dl_[a]; }
  // The rational value of origin + t * dir along axis a.
  mpq_class PointAt(const T& t, int a) const;

  mutable uint64_t exact_fallbacks = 0;  // how often the filter could not decide

 private:
  Ray ray_;
  long double ol_[3], dl_[3];
  mpq_class oq_[3], dq_[3];
};

// How the ray meets one axis-aligned box [lo, hi] (closed) / [lo, hi) (half-open).
struct Contact {
  bool touch = false;     // meets the closed box
  bool meets = false;     // meets the half-open box in positive length
  ExactRay::T tin, tout;  // valid when touch
};
Contact BoxContact(const ExactRay& ray, const int64_t lo[3], const int64_t hi[3]);
Contact VoxelContact(const ExactRay& ray, const Voxel& v);

struct RefHit {
  bool hit = false;
  Voxel voxel{};
  ExactRay::T tin;         // entry parameter (when hit)
  bool ambiguous = false;  // another occupied voxel is touched at <= tin
  // Occupied voxels touched (not met, or met at the same entry) at <= tin, or
  // every touched one on a miss.
  std::vector<Voxel> touched;
};

struct RefContact {
  Voxel voxel{};
  Contact contact;
};

class Reference {
 public:
  // REQUIRES: 1 <= levels <= 40, voxels inside [0, 2^levels)^3 (duplicates OK).
  Reference(const std::vector<Voxel>& voxels, int levels);

  int levels() const { return levels_; }
  size_t size() const { return num_voxels_; }
  bool Occupied(const Voxel& v) const;
  RefHit FirstHit(const ExactRay& ray) const;
  // Every occupied voxel whose closed cube the ray touches, sorted by entry
  // parameter (ties in no particular order).
  std::vector<RefContact> AllTouched(const ExactRay& ray) const;

 private:
  struct Slot {
    uint64_t x = 0, y = 0, z = 0;
    uint8_t mask = 0;
    bool used = false;
  };
  struct Table {
    std::vector<Slot> slots;
    size_t count = 0;
    uint8_t* Find(uint64_t x, uint64_t y, uint64_t z, bool insert);
    uint8_t Get(uint64_t x, uint64_t y, uint64_t z) const;
  };
  struct Search;
  void Visit(Search& s, int k, const uint64_t c[3]) const;

  int levels_ = 0;
  size_t num_voxels_ = 0;
  std::vector<Table> tables_;  // tables_[k]: child masks of occupied level-k cells, k >= 1
};

// Why a tracer's first-hit answer is unacceptable, or "" when it is
// acceptable. The rule: when the reference hits unambiguously, the tracer
// must hit that voxel; when the reference's hit is ambiguous, any occupied
// voxel the ray touches at or before the reference's entry; when the
// reference misses, a miss or any occupied voxel the ray touches. The hit's t
// must match the exact entry (touch) parameter of its voxel to 1e-9
// (relative, or absolute near 0).
std::string CheckFirstHit(const Reference& ref, const ExactRay& ray, const RefHit& expected,
                          const std::optional<Hit>& got);
// For an answer CheckFirstHit refuses: true when it is explained by a ray
// passing within `eps` voxels of a lattice edge or face, i.e. it would be
// acceptable for a ray perturbed by at most that much: the tracer's voxel,
// grown by eps, is touched no later than the reference's entry (plus eps
// along the ray); or every voxel the ray meets (up to the tracer's) is met
// over less than eps. Precision failures, as opposed to logic ones.
bool WithinEpsilon(const Reference& ref, const ExactRay& ray, const RefHit& expected,
                   const std::optional<Hit>& got, double eps);

// Why a tracer's Traverse list is unacceptable, or "".
std::string CheckTraversal(const Reference& ref, const ExactRay& ray,
                           const std::vector<Hit>& got);

// "origin (0x1p+0, ...) dir (...)" in C99 hex floats, for failure messages.
std::string RayString(const Ray& ray);
std::string VoxelString(const Voxel& v);
Voxel ToVoxel(const Hit& h);

}  // namespace vox::testing

#endif  // VOX_TESTS_STUDY_REFERENCE_H_

#include "render/beam.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

namespace vox {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// The frustum of a block: four side planes dot(n, P) >= c (inside), the
// near bound s >= s_near, and the direction g of s = dot(g, P).
struct Frustum {
  glm::dvec3 n[4];
  double c[4] = {};
  int planes = 0;
  glm::dvec3 g;
  double s_near = 0;

  // Whether the box [lo, lo + size]^3, widened by m on every side, may meet
  // the frustum (false only when it cannot); *s_lo: the least s on the box.
  bool Meets(const double lo[3], double size, double m, double* s_lo) const {
    const double h = 0.5 * size + m;
    const glm::dvec3 ctr(lo[0] + 0.5 * size, lo[1] + 0.5 * size, lo[2] + 0.5 * size);
    const double gs = glm::dot(g, ctr), gr = h * (std::fabs(g.x) + std::fabs(g.y) + std::fabs(g.z));
    if (gs + gr < s_near) return false;  // behind every ray's origin
    for (int i = 0; i < planes; ++i) {
      const double r = h * (std::fabs(n[i].x) + std::fabs(n[i].y) + std::fabs(n[i].z));
      if (glm::dot(n[i], ctr) + r < c[i]) return false;  // wholly outside a side plane
    }
    *s_lo = gs - gr;
    return true;
  }
};

}  // namespace

StartPlane BeamStartPlane(const OctreeView& tree, int n1, const BeamCorners& beam,
                          uint64_t* cells_tested) {
  StartPlane none;  // s_min = -inf: no hint
  if (tree.top == nullptr || tree.levels < 1 || n1 < 1) return none;
  Frustum f;
  glm::dvec3 dsum(0.0), osum(0.0);
  const double grid = std::ldexp(1.0, tree.levels);
  for (int i = 0; i < 4; ++i) {
    if (!Finite(beam.o[i]) || !Finite(beam.d[i])) return none;
    // Far origins: the side planes through them would lose the cells'
    // position next to |o| in double (the tracer clips such rays exactly).
    if (IsFarOrigin(beam.o[i], grid)) return none;
    const double len = glm::length(beam.d[i]);
    if (!(len > 0) || !std::isfinite(len)) return none;
    dsum += beam.d[i] / len;
    osum += beam.o[i];
  }
  const double glen = glm::length(dsum);
  if (!(glen > 0)) return none;
  f.g = dsum / glen;
  for (int i = 0; i < 4; ++i)
    if (!(glm::dot(f.g, beam.d[i]) > 0)) return none;  // over 90 degrees from the mean
  // A point inside the beam, to orient the side planes.
  const glm::dvec3 inside = 0.25 * osum + f.g;
  f.s_near = kInf;
  for (int i = 0; i < 4; ++i) {
    f.s_near = std::min(f.s_near, glm::dot(f.g, beam.o[i]));
    const int j = (i + 1) % 4;
    // The plane through ray i holding ray j too (rays of a pinhole share
    // their origin; an orthographic camera's share their direction).
    glm::dvec3 n = glm::cross(beam.d[i], beam.o[j] + beam.d[j] - beam.o[i]);
    const double nl = glm::length(n);
    if (!(nl > 0) || !std::isfinite(nl)) continue;  // degenerate: no bound from it
    n /= nl;
    double c = glm::dot(n, beam.o[i]);
    if (glm::dot(n, inside) < c) {
      n = -n;
      c = -c;
    }
    f.n[f.planes] = n;
    f.c[f.planes] = c;
    ++f.planes;
  }

  const int leaf_level = std::min(n1, tree.brick_level);  // occupied units: cells of this level
  const double m = kStartPlaneMargin;
  struct Node {
    uint32_t index;
    int level;
    double lo[3];
    double s_lo;
  };
  Node stack[8 * (kMaxLevels + 1)];
  int top = 0;
  uint64_t tests = 1;
  double best = kInf;
  const double root_size = std::ldexp(1.0, tree.levels);
  Node root{0, 0, {0, 0, 0}, 0};
  if (!f.Meets(root.lo, root_size, m, &root.s_lo)) {
    if (cells_tested) *cells_tested += tests;
    StartPlane miss = StartPlane{{f.g.x, f.g.y, f.g.z}, kInf};
    return miss;
  }
  stack[top++] = root;
  while (top > 0) {
    const Node node = stack[--top];
    if (node.s_lo >= best) continue;
    const CompactCell cell = tree.top[node.index];
    const uint32_t mask = ChildMask(cell);
    const double half = std::ldexp(1.0, tree.levels - node.level - 1);
    Node kids[8];
    int nk = 0;
    for (unsigned digit = 0; digit < 8; ++digit) {
      if (!((mask >> digit) & 1u)) continue;
      Node k{0,
             node.level + 1,
             {node.lo[0] + ((digit & 1) ? half : 0.0), node.lo[1] + ((digit & 2) ? half : 0.0),
              node.lo[2] + ((digit & 4) ? half : 0.0)},
             0};
      ++tests;
      if (!f.Meets(k.lo, half, m, &k.s_lo) || k.s_lo >= best) continue;
      if (k.level == leaf_level) {
        best = k.s_lo;  // an occupied unit the beam may meet
        continue;
      }
      k.index = ChildIndex(cell, digit);
      kids[nk++] = k;
    }
    // Nearest child on top of the stack: front to back.
    for (int i = 1; i < nk; ++i)  // insertion sort, farthest first (at most 8)
      for (int j = i; j > 0 && kids[j - 1].s_lo < kids[j].s_lo; --j)
        std::swap(kids[j - 1], kids[j]);
    for (int i = 0; i < nk; ++i) stack[top++] = kids[i];
  }
  if (cells_tested) *cells_tested += tests;
  return StartPlane{{f.g.x, f.g.y, f.g.z}, best};
}

}  // namespace vox

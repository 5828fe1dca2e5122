#include "core/ray.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace vox {

Status ValidateRay(const Ray& ray) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(ray.origin[a]) || !std::isfinite(ray.dir[a])) {
      std::ostringstream m;
      m << "ray has a non-finite component: origin (" << ray.origin.x << ", " << ray.origin.y
        << ", " << ray.origin.z << ") direction (" << ray.dir.x << ", " << ray.dir.y << ", "
        << ray.dir.z << ")";
      return InvalidArgumentError(m.str());
    }
  }
  if (ray.dir.x == 0 && ray.dir.y == 0 && ray.dir.z == 0)
    return InvalidArgumentError("ray direction is zero");
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(ray.origin[a]) > kMaxOriginMagnitude) {
      std::ostringstream m;
      m << "ray origin component " << ray.origin[a]
        << " is too far: origins must be within +-2^1000 (about 1.07e301)";
      return InvalidArgumentError(m.str());
    }
  }
  return OkStatus();
}

void TraceCounters::Add(const TraceCounters& o) {
  rays += o.rays;
  for (int a = 0; a < 3; ++a) moves[a] += o.moves[a];
  driving_moves += o.driving_moves;
  passive_moves += o.passive_moves;
  skips += o.skips;
  cells_visited += o.cells_visited;
  transitions += o.transitions;
  brick_fetches += o.brick_fetches;
  hits += o.hits;
}

std::string TraceCounters::ToString() const {
  std::ostringstream s;
  s << "rays " << rays << ", hits " << hits << ", moves " << total_moves() << " (x " << moves[0]
    << ", y " << moves[1] << ", z " << moves[2] << "; driving " << driving_moves << ", passive "
    << passive_moves << "), skips " << skips << ", cells " << cells_visited << ", transitions "
    << transitions << ", brick fetches " << brick_fetches;
  return s.str();
}


namespace {

// Error-free transformations (Knuth, Dekker; fma): a + b = s + e and
// a * b = p + e exactly (barring overflow and underflow).
void TwoSum(double a, double b, double* s, double* e) {
  *s = a + b;
  const double bb = *s - a;
  *e = (a - (*s - bb)) + (b - bb);
}
void TwoProd(double a, double b, double* p, double* e) {
  *p = a * b;
  *e = std::fma(a, b, -*p);
}

// The sum of `n` doubles, exact as an expansion (Shewchuk's Grow-Expansion),
// rounded at the end in long double from the smallest component up.
long double ExactSum(const double* x, int n) {
  double e[16];
  int m = 0;
  for (int i = 0; i < n; ++i) {
    double q = x[i];
    int k = 0;
    for (int j = 0; j < m; ++j) {
      double sum, err;
      TwoSum(q, e[j], &sum, &err);
      q = sum;
      if (err != 0) e[k++] = err;
    }
    if (q != 0) e[k++] = q;
    m = k;
  }
  long double r = 0;
  for (int j = 0; j < m; ++j) r += e[j];
  return r;
}

}  // namespace

bool ClipFarRay(const glm::dvec3& o, const double D[3], const int s[3], double G, long double p[3],
                long double* t_start) {
  // Axes the ray does not move along: half-open, as the usual clipping.
  for (int a = 0; a < 3; ++a)
    if (D[a] == 0 && (s[a] > 0 ? (o[a] < 0 || o[a] >= G) : (o[a] <= 0 || o[a] > G))) return false;
  int best = -1;
  long double best_t = 0;
  for (int d = 0; d < 3; ++d) {
    if (D[d] == 0) continue;
    const double near = s[d] > 0 ? 0.0 : G;
    // The crossing of the plane x_d = near must be ahead (t >= 0) and the
    // origin outside the slab on this axis (else the entry is elsewhere).
    if (s[d] > 0 ? !(o[d] <= near) : !(o[d] >= near)) continue;
    long double q[3];
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      if (a == d) {
        q[a] = near;
      } else if (D[a] == 0) {
        q[a] = o[a];
      } else {
        // q_a = o_a + (near - o_d) D_a / D_d = (o_a D_d - o_d D_a + near D_a) / D_d.
        double terms[6];
        TwoProd(o[a], D[d], &terms[0], &terms[1]);
        TwoProd(-o[d], D[a], &terms[2], &terms[3]);
        TwoProd(near, D[a], &terms[4], &terms[5]);
        q[a] = ExactSum(terms, 6) / (long double)D[d];
        // Entering through face d: on the grid along a, and not leaving
        // through a's far face at once (positive length).
        inside = s[a] > 0 ? (q[a] >= 0 && q[a] < G) : (q[a] > 0 && q[a] <= G);
      }
    }
    if (!inside) continue;
    const long double t = ((long double)near - (long double)o[d]) / (long double)D[d];
    if (best < 0 || t > best_t) {
      best = d;
      best_t = t;
      for (int a = 0; a < 3; ++a) p[a] = q[a];
    }
  }
  if (best < 0) return false;
  for (int a = 0; a < 3; ++a) p[a] = std::clamp(p[a], 0.0L, (long double)G);
  *t_start = best_t;
  return true;
}


}  // namespace vox

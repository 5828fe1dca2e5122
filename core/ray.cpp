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
double SlabT(const Ray& ray, const glm::i64vec3& v, bool entry) {
  double best = entry ? 0.0 : std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    double dir = ray.dir[a];
    if (dir == 0) continue;
    bool pos = dir > 0;
    double face = double(v[a]) + ((pos == entry) ? 0.0 : 1.0);
    double t = (face - ray.origin[a]) / dir;
    best = entry ? std::max(best, t) : std::min(best, t);
  }
  return best;
}
}  // namespace

double VoxelEntryT(const Ray& ray, const glm::i64vec3& v) { return SlabT(ray, v, true); }
double VoxelExitT(const Ray& ray, const glm::i64vec3& v) { return SlabT(ray, v, false); }

}  // namespace vox

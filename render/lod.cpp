// LodTracer: the segment-by-segment trace of a ray cone over a
// level-of-detail pyramid (render/lod.h).
#include "render/lod.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace vox {
namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}  // namespace

StatusOr<double> ParseLodFactor(const std::string& flag, const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const double f = std::strtod(text.c_str(), &end);
  if (text.empty() || end == nullptr || *end != '\0' || errno == ERANGE)
    return InvalidArgumentError(flag + " '" + text + "': expected a number > 0");
  if (!std::isfinite(f)) return InvalidArgumentError(flag + " '" + text + "': must be finite");
  if (!(f > 0)) return InvalidArgumentError(flag + " '" + text + "': must be > 0");
  return f;
}

StatusOr<LodTracer> LodTracer::Create(Volume* base, const std::vector<Volume*>& levels,
                                      double factor) {
  if (!(factor > 0) || !std::isfinite(factor))
    return InvalidArgumentError("--lod factor " + std::to_string(factor) +
                                ": must be finite and > 0");
  LodTracer t;
  t.base_ = base;
  t.levels_ = levels;
  t.factor_ = factor;
  const StoreMeta& m = base->meta();
  for (size_t i = 0; i < levels.size(); ++i) {
    const OctreeView v = levels[i]->view();
    if (v.levels != m.levels - int(i + 1))
      return InvalidArgumentError("level-of-detail level " + std::to_string(i + 1) + " has " +
                                  std::to_string(v.levels) + " levels; the base has " +
                                  std::to_string(m.levels));
    VOX_ASSIGN_OR_RETURN(LodLevelTracer tr,
                         LodLevelTracer::Create(v, DefaultFirstStepLevels(v.levels)));
    t.tracers_.push_back(tr);
  }
  if (m.voxel_count > 0) {
    t.box_lo_ = glm::dvec3(m.bbox_min - m.origin);
    t.box_hi_ = glm::dvec3(m.bbox_max - m.origin) + 1.0;
  }
  return t;
}

int LodTracer::LevelForWidth(double w) const {
  const double fw = factor_ * w;
  if (!(fw >= 2.0)) return 0;
  if (!std::isfinite(fw)) return max_level();
  return std::min(std::ilogb(fw), max_level());
}

double LodTracer::LevelStart(const Cone& cone, int l) const {
  const double target = std::ldexp(1.0, l) / factor_;  // the width where level l begins
  if (cone.w0 >= target) return 0.0;
  if (!(cone.spread > 0)) return kInf;
  return std::max(0.0, (target - cone.w0) / cone.spread);
}

void LodTracer::BoxSpan(const Ray& gr, double* t_in, double* t_out) const {
  double lo = 0.0, hi = kInf;
  for (int a = 0; a < 3; ++a) {
    if (gr.dir[a] == 0) {
      if (gr.origin[a] < box_lo_[a] || gr.origin[a] > box_hi_[a]) lo = kInf;
      continue;
    }
    double t0 = (box_lo_[a] - gr.origin[a]) / gr.dir[a];
    double t1 = (box_hi_[a] - gr.origin[a]) / gr.dir[a];
    if (t0 > t1) std::swap(t0, t1);
    lo = std::max(lo, t0);
    hi = std::min(hi, t1);
  }
  if (!(box_lo_.x <= box_hi_.x)) lo = kInf;  // empty volume
  *t_in = lo;
  *t_out = hi;
}

bool LodTracer::Exact(const Ray& gr, const Cone& cone) const {
  if (levels_.empty()) return true;
  double t_in, t_out;
  BoxSpan(gr, &t_in, &t_out);
  if (!(t_in <= t_out)) return true;
  return LevelStart(cone, 1) >= t_out;
}

Status LodTracer::Traverse(const LodLevelTracer& base, const Ray& gr, const Cone& cone,
                           const std::function<bool(const LodSegment&)>& visit,
                           TraceCounters* counters) const {
  double t_in, t_out;
  BoxSpan(gr, &t_in, &t_out);
  if (!(t_in <= t_out)) return OkStatus();
  const int top = max_level();
  double t_a = 0.0;
  int l = LevelForWidth(cone.Width(std::max(0.0, t_in)));
  while (l < top && LevelStart(cone, l + 1) <= t_a) ++l;
  bool stopped = false;  // the visitor said stop
  while (!stopped) {
    const double t_b = l < top ? LevelStart(cone, l + 1) : kInf;
    LodSegment seg;
    seg.level = l;
    if (l == 0) {
      seg.volume = base_;
      VOX_RETURN_IF_ERROR(base.Traverse(
          gr,
          [&](const Hit& h) {
            if (h.t >= t_b) return false;  // the segment ends
            seg.hit = h;
            seg.t0 = h.t;
            seg.t1 = std::min(VoxelExitT(gr, h.voxel), t_b);
            if (!visit(seg)) stopped = true;
            return !stopped;
          },
          counters));
    } else {
      const double start = std::max(t_a, t_in);
      if (start >= t_out) break;
      const double s = std::ldexp(1.0, -l);
      const Ray cr{(gr.origin + start * gr.dir) * s, gr.dir * s};
      seg.volume = levels_[size_t(l - 1)];
      VOX_RETURN_IF_ERROR(tracers_[size_t(l - 1)].Traverse(
          cr,
          [&](const Hit& h) {
            const double t0 = start + h.t;
            if (t0 >= t_b) return false;
            seg.hit = h;
            seg.t0 = t0;
            seg.t1 = std::min(start + VoxelExitT(cr, h.voxel), t_b);
            if (!visit(seg)) stopped = true;
            return !stopped;
          },
          counters));
    }
    if (stopped || t_b >= t_out) break;
    t_a = t_b;
    ++l;
    while (l < top && LevelStart(cone, l + 1) <= t_a) ++l;
  }
  return OkStatus();
}

StatusOr<bool> LodTracer::FirstHit(const LodLevelTracer& base, const Ray& gr, const Cone& cone,
                                   bool skip_start_run, double eps, LodSegment* out,
                                   VoxelAttributes* attrs, TraceCounters* counters) const {
  bool run_active = skip_start_run, found = false;
  double run_end = 0.0;
  Status attr_error;
  VOX_RETURN_IF_ERROR(Traverse(
      base, gr, cone,
      [&](const LodSegment& seg) {
        if (run_active && seg.t0 <= run_end + eps * (1.0 + run_end)) {
          run_end = std::max(run_end, seg.t1);
          return true;
        }
        *out = seg;
        found = true;
        if (attrs != nullptr) {
          // While the traversal pins the cell's brick.
          StatusOr<VoxelAttributes> a = seg.volume->HitAttributes(seg.hit);
          if (!a.ok()) {
            attr_error = a.status();
            found = false;
          } else {
            *attrs = *a;
          }
        }
        return false;
      },
      counters));
  VOX_RETURN_IF_ERROR(attr_error);
  if (found && counters != nullptr) ++counters->hits;
  return found;
}

}  // namespace vox

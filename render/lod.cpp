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
// A LodThread's table keys a coarse brick by its level in the top bits.
constexpr int kLevelTagShift = 26;
constexpr uint32_t kIdMask = (uint32_t(1) << kLevelTagShift) - 1;
}  // namespace

void ClipToOccupiedBox(const StoreMeta& m, LodLevelTracer* t) {
  if (m.voxel_count == 0) return;
  const int64_t lo[3] = {m.bbox_min.x - m.origin.x, m.bbox_min.y - m.origin.y,
                         m.bbox_min.z - m.origin.z};
  const int64_t hi[3] = {m.bbox_max.x - m.origin.x, m.bbox_max.y - m.origin.y,
                         m.bbox_max.z - m.origin.z};
  if (lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]) return;
  t->SetOccupiedBox(lo, hi);
}

// The table's shared source: brick (level << kLevelTagShift | id) of the
// level's store.
class LodThread::Levels : public BrickSource {
 public:
  explicit Levels(std::vector<BrickSource*> sources) : sources_(std::move(sources)) {}
  StatusOr<BrickView> FetchBrick(uint32_t tagged) override {
    return Source(tagged)->FetchBrick(tagged & kIdMask);
  }
  StatusOr<BrickView> FetchBrickIfReady(uint32_t tagged) override {
    return Source(tagged)->FetchBrickIfReady(tagged & kIdMask);
  }

 private:
  BrickSource* Source(uint32_t tagged) const {
    return sources_[size_t(tagged >> kLevelTagShift) - 1];
  }
  std::vector<BrickSource*> sources_;  // level l at l - 1
};

// Level `level`'s bricks, lent by the thread's table under their tag.
class LodThread::Tagged : public BrickSource {
 public:
  Tagged(LendingBrickTable* table, int level)
      : table_(table), tag_(uint32_t(level) << kLevelTagShift) {}
  StatusOr<BrickView> FetchBrick(uint32_t id) override { return table_->FetchBrick(tag_ | id); }
  bool lends() const override { return true; }
  const BrickView* LendBrick(uint32_t id, Status* error) override {
    return table_->LendBrick(tag_ | id, error);
  }
  const uint64_t* lend_epoch() const override { return table_->lend_epoch(); }

 private:
  LendingBrickTable* table_;
  uint32_t tag_;
};

LodThread::~LodThread() = default;

Cone PrimaryConeOf(const Camera& cam, double voxel_size) {
  const double vs = std::max(voxel_size, 1e-300);
  Cone c;
  if (cam.projection == Projection::kPerspective)
    c.spread =
        2.0 * std::tan(cam.HorizontalFovDeg() * (3.14159265358979323846 / 360.0)) / cam.width / vs;
  else
    c.w0 = cam.ortho_width / cam.width / vs;
  return c;
}

StatusOr<double> ParseLodFactor(const std::string& flag, const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const double f = std::strtod(text.c_str(), &end);
  if (text.empty() || end == nullptr || *end != '\0' || errno == ERANGE)
    return InvalidArgumentError(flag + " '" + text + "': expected a number >= 0 (0: exact)");
  if (!std::isfinite(f)) return InvalidArgumentError(flag + " '" + text + "': must be finite");
  if (!(f >= 0)) return InvalidArgumentError(flag + " '" + text + "': must be >= 0 (0: exact)");
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
    ClipToOccupiedBox(levels[i]->meta(), &tr);
    t.tracers_.push_back(tr);
  }
  if (m.voxel_count > 0) {
    t.box_lo_ = glm::dvec3(m.bbox_min - m.origin);
    t.box_hi_ = glm::dvec3(m.bbox_max - m.origin) + 1.0;
  }
  return t;
}

std::unique_ptr<LodThread> LodTracer::NewThread(int slot_bits) const {
  std::unique_ptr<LodThread> th(new LodThread());
  th->tracers_ = tracers_;
  std::vector<BrickSource*> sources;
  for (Volume* v : levels_) sources.push_back(v->view().bricks);
  th->levels_ = std::make_unique<LodThread::Levels>(sources);
  th->table_ = std::make_unique<LendingBrickTable>(th->levels_.get(), slot_bits);
  for (size_t i = 0; i < levels_.size(); ++i) {
    const int level = int(i + 1);
    OctreeView v = levels_[i]->view();
    // Tags need the level to fit above the ids (tags 1..63, ids < 2^26).
    if (v.bricks == nullptr || level >= 64 || levels_[i]->meta().brick_count > kIdMask + uint64_t(1))
      continue;
    th->tagged_.push_back(std::make_unique<LodThread::Tagged>(th->table_.get(), level));
    v.bricks = th->tagged_.back().get();
    auto t = LodLevelTracer::Create(v, tracers_[i].n1());
    if (!t.ok()) continue;  // cannot fail: the same tree and split as tracers_[i]
    ClipToOccupiedBox(levels_[i]->meta(), &*t);
    th->tracers_[i] = *t;
  }
  return th;
}

int LodTracer::FirstLevelSeen(const Camera& camera, const Cone& cone, const glm::dvec3& lo,
                              const glm::dvec3& hi) const {
  double t = 0.0;
  if (camera.projection == Projection::kPerspective) {
    const glm::dvec3 nearest = glm::clamp(camera.position, lo, hi);
    t = glm::length(camera.position - nearest) * (1.0 - 1e-9);  // conservative
  }
  if (!std::isfinite(t)) return 0;
  return LevelForWidth(cone.Width(t));
}

int LodTracer::LevelForWidth(double w) const {
  const double fw = factor_ * w;
  if (!(fw >= 2.0)) return 0;
  if (!std::isfinite(fw)) return max_level();
  return std::min(std::ilogb(fw), max_level());
}

double LodTracer::LevelStart(const Cone& cone, int l) const {
  const double target = Pow2(l) / factor_;  // the width where level l begins
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

StatusOr<bool> LodTracer::FirstHit(const LodLevelTracer& base, const LodThread* thread,
                                   const Ray& gr, const Cone& cone, bool skip_start_run,
                                   double eps, LodSegment* out, VoxelAttributes* attrs,
                                   TraceCounters* counters, const StartPlane* start) const {
  bool run_active = skip_start_run, found = false;
  double run_end = 0.0;
  Status attr_error;
  VOX_RETURN_IF_ERROR(Traverse(
      base, thread, gr, cone,
      [&](const LodSegment& seg) {
        if (run_active && seg.t0 <= run_end + eps * (1.0 + run_end)) {
          run_end = std::max(run_end, seg.ExitT());
          return true;
        }
        *out = seg;
        out->walk = nullptr;  // (the walk's ray ends with it: ExitT is for visitors)
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
      counters, start));
  VOX_RETURN_IF_ERROR(attr_error);
  if (found && counters != nullptr) ++counters->hits;
  return found;
}

}  // namespace vox

// The Renderer's level-of-detail rays (render/lod.h, docs/lod.md): first
// hits of a ray cone over the pyramid, and the shadow and reflection rays
// of a coarse hit, which carry the cone on; and the exact pick of a coarse
// primary stop (the voxel, position and Z layers).
#include "render/internal/tracing.h"
#include "render/renderer.h"

namespace vox {

bool Renderer::FindHitLod(const Ray& gr, const Cone& cone, bool skip_start_run, TraceContext& cx,
                          Hit* hit, int* level, VoxelAttributes* attrs,
                          const StartPlane* start) const {
  if (lod_->Exact(gr, cone)) {
    ++cx.c->lod.exact_rays;
    *level = 0;
    const bool found = FindHit(gr, skip_start_run, cx, hit, attrs, start);
    if (found) ++cx.c->lod.stops[0];
    return found;
  }
  LodSegment seg;
  if (attrs != nullptr) ++cx.c->attribute_lookups;
  StatusOr<bool> found =
      lod_->FirstHit(*cx.tracer, cx.lod, gr, cone, skip_start_run, eps_t_, &seg, attrs,
                     &cx.c->trace, start);
  if (!found.ok()) {
    cx.Fail(found.status());
    return false;
  }
  if (!*found) return false;
  *hit = seg.hit;
  hit->t = seg.t0;  // the unscaled ray's parameter; the voxel stays in its level's grid
  *level = seg.level;
  ++cx.c->lod.stops[seg.level];
  return true;
}

void Renderer::PickExactly(const WorldRay& wr, TraceContext& cx, Sample* s,
                           const StartPlane* start) const {
  if (!s->hit || s->level == 0 || fog_ || !(options_.layers.voxel || options_.layers.position)) return;
  const Ray gr{xf_.WorldToGrid(wr.origin), xf_.world_to_grid_linear * wr.dir};
  Hit h;
  if (!FindHit(gr, /*skip_start_run=*/false, cx, &h, nullptr, start)) {
    s->z = render_internal::kInf;  // a coarse cell with no voxel on this ray: no pick
    s->depth = render_internal::kInf;
    return;
  }
  s->z = h.t;
  SetHitGeometry(wr, s);
  s->voxel = h.voxel + volume_->meta().origin;
}

bool Renderer::OccludedLod(const Ray& gr, double t_max, const Cone& cone, TraceContext& cx) const {
  ++cx.c->rays[kRayShadow];
  Hit h;
  int level = 0;
  if (!FindHitLod(gr, cone, /*skip_start_run=*/true, cx, &h, &level, nullptr)) return false;
  return h.t < t_max;
}

glm::dvec3 Renderer::RadianceLod(const Ray& gr, const glm::dvec3& dir_w, int depth, int kind,
                                 const Cone& cone, TraceContext& cx) const {
  ++cx.c->rays[kind];
  Hit h;
  VoxelAttributes a;
  int level = 0;
  if (!FindHitLod(gr, cone, /*skip_start_run=*/true, cx, &h, &level, SurfaceAttrs(&a)))
    return cx.failed() ? glm::dvec3(0.0) : Background(dir_w);
  const LodRay lr{cone, level};
  return ShadeSurface(gr, dir_w, h, a, depth, cx, nullptr, &lr);
}

}  // namespace vox

// The Renderer's fog volumes: absorption and single scattering along a
// primary ray, and the transmittance of the rays towards the lights.
#include <algorithm>
#include <cmath>

#include "render/internal/tracing.h"
#include "render/renderer.h"

namespace vox {

using render_internal::ForEachLight;
using render_internal::kInf;
using render_internal::kMaxOpticalDepth;

double Renderer::Transmittance(const Ray& gr, double t_max, TraceContext& cx, const Cone* cone) const {
  ++cx.c->rays[kRayVolume];
  const double sigma_t = scene_.volume.absorption + scene_.volume.scattering;
  const bool has_density = volume_->meta().has_density;
  double tau = 0.0;
  if (cone != nullptr && !lod_->Exact(gr, *cone)) {
    // Level of detail: each coarse cell's mean density over its segment.
    Status s = lod_->Traverse(
        *cx.tracer, cx.lod, gr, *cone,
        [&](const LodSegment& seg) {
          if (seg.t0 >= t_max) return false;
          const double t1 = std::min(seg.t1, t_max);
          double rho = 1.0;
          if ((seg.level > 0 || has_density) && !Density(seg.hit, cx, &rho, seg.volume))
            return false;
          tau += sigma_t * rho * std::max(0.0, t1 - seg.t0);
          return tau <= kMaxOpticalDepth;
        },
        &cx.c->trace);
    if (!s.ok()) cx.Fail(s);
    return std::exp(-tau);
  }
  Status s = cx.tracer->Traverse(
      gr,
      [&](const Hit& h) {
        if (h.t >= t_max) return false;
        double t1 = std::min(VoxelExitT(gr, h.voxel), t_max);
        double rho = 1.0;
        if (has_density && !Density(h, cx, &rho)) return false;
        tau += sigma_t * rho * std::max(0.0, t1 - h.t);
        return tau <= kMaxOpticalDepth;
      },
      &cx.c->trace);
  if (!s.ok()) cx.Fail(s);
  return std::exp(-tau);
}

// The density of fog voxel `h` (stops the frame with the error on failure).
bool Renderer::Density(const Hit& h, TraceContext& cx, double* rho, Volume* volume) const {
  ++cx.c->attribute_lookups;
  auto a = (volume != nullptr ? volume : volume_)->HitAttributes(h);  // called by visitors: h's brick is pinned
  if (!a.ok()) {
    cx.Fail(a.status());
    return false;
  }
  *rho = a->density;
  return true;
}

glm::dvec3 Renderer::LightInFog(const Ray& gr, double t, TraceContext& cx, const Cone* cone) const {
  const glm::dvec3 p_g = gr.origin + t * gr.dir;
  const glm::dvec3 p_w = xf_.GridToWorld(p_g);
  // With a pyramid, the transmittance ray's cells widen along it (at least
  // as fast as the primary ray's cone): the light's path far from the point
  // is seen coarsely, near it exactly.
  Cone shadow_cone;
  const Cone* sc = nullptr;
  if (cone != nullptr) {
    shadow_cone = SecondaryCone(*cone, t);
    const double g = scene_.volume.shadow_lod;
    if (g > 0) shadow_cone.spread = std::max(shadow_cone.spread, 1.0 / (g * volume_->meta().voxel_size));
    sc = &shadow_cone;
  }
  glm::dvec3 light_in(0.0);
  ForEachLight(scene_.lights, p_w, [&](const Light& l, const glm::dvec3& to_light, double dist) {
    const double tl = l.shadows ? Transmittance(SpawnRay(p_g, to_light), dist, cx, sc) : 1.0;
    light_in += l.color * l.intensity * tl;
  });
  return light_in;
}

glm::dvec3 Renderer::Fog(const Ray& gr, TraceContext& cx, double* transmittance, double* first_t,
                         const Cone* cone) const {
  const VolumeMedium& v = scene_.volume;
  const double sigma_t = v.absorption + v.scattering;
  const bool has_density = volume_->meta().has_density;
  double tau = 0.0, trans = 1.0;
  glm::dvec3 scattered(0.0);
  // The light reaching the ray at sample points ta < tb, interpolated
  // linearly in between. The next sample is light_step voxels on (times the
  // cone's width with LOD), or less where the fog is thick: at most
  // light_optical_depth of the extinction of the cell the sample lies in.
  // The samples start where the ray enters the fog, and again at the next
  // cell after an empty gap longer than a step.
  const double light_step = v.light_step * volume_->meta().voxel_size;  // t is in world units
  auto step_from = [&](double t, double extinction) {
    const double h = cone != nullptr ? light_step * std::max(1.0, cone->Width(t)) : light_step;
    return extinction > 0 ? std::min(h, v.light_optical_depth / extinction) : h;
  };
  double ta = -kInf, tb = -kInf;
  glm::dvec3 la(0.0), lb(0.0);
  *first_t = kInf;
  // One occupied cell [t0, t1] of density rho (Cone: `level` > 0 for coarse cells).
  auto cell = [&](double t0, double t1, double rho) {
    if (*first_t == kInf) *first_t = t0;
    const double len = std::max(0.0, t1 - t0);
    const double st = sigma_t * rho;
    if (st <= 0) return true;
    const double seg_tau = st * len;
    const double seg_trans = std::exp(-seg_tau);
    if (passes_.scattering) {
      const double mid = t0 + 0.5 * len;
      while (mid > tb) {
        const bool restart = t0 > tb;
        ta = restart ? t0 : tb;
        la = restart ? LightInFog(gr, ta, cx, cone) : lb;
        tb = ta + step_from(ta, st);
        lb = LightInFog(gr, tb, cx, cone);
      }
      const double w = std::clamp((mid - ta) / (tb - ta), 0.0, 1.0);
      const glm::dvec3 light_in = la + w * (lb - la);
      scattered += trans * (1.0 - seg_trans) * (v.scattering / sigma_t) * v.color * light_in;
    }
    tau += seg_tau;
    trans *= seg_trans;
    return !cx.failed() && tau <= kMaxOpticalDepth;
  };
  Status s;
  if (cone != nullptr && !lod_->Exact(gr, *cone)) {
    s = lod_->Traverse(
        *cx.tracer, cx.lod, gr, *cone,
        [&](const LodSegment& seg) {
          double rho = 1.0;
          if ((seg.level > 0 || has_density) && !Density(seg.hit, cx, &rho, seg.volume))
            return false;
          return cell(seg.t0, seg.t1, rho);
        },
        &cx.c->trace);
  } else {
    s = cx.tracer->Traverse(
        gr,
        [&](const Hit& h) {
          double rho = 1.0;
          if (has_density && !Density(h, cx, &rho)) return false;
          return cell(h.t, VoxelExitT(gr, h.voxel), rho);
        },
        &cx.c->trace);
  }
  if (!s.ok()) cx.Fail(s);
  *transmittance = std::exp(-tau);
  return scattered;
}

}  // namespace vox

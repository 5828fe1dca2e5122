// The Renderer's fog volumes: absorption and single scattering along a
// primary ray, and the transmittance of the rays towards the lights.
#include <algorithm>
#include <cmath>

#include "render/internal/tracing.h"
#include "render/renderer.h"

namespace vox {

using render_internal::ForEachLight;
using render_internal::kInf;
using render_internal::kMinTransmittance;
using render_internal::kScatterStepVoxels;

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
          return std::exp(-tau) >= kMinTransmittance;
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
        return std::exp(-tau) >= kMinTransmittance;
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

glm::dvec3 Renderer::Fog(const Ray& gr, TraceContext& cx, double* transmittance, double* first_t,
                         const Cone* cone) const {
  const VolumeMedium& v = scene_.volume;
  const double sigma_t = v.absorption + v.scattering;
  const bool has_density = volume_->meta().has_density;
  double tau = 0.0;
  glm::dvec3 scattered(0.0), light_in(0.0);
  double next_light_t = -kInf;
  // Ray parameter per voxel along this ray (t is in world units).
  const double scatter_step = kScatterStepVoxels * volume_->meta().voxel_size;
  *first_t = kInf;
  // One occupied cell [t0, t1] of density rho (Cone: `level` > 0 for coarse cells).
  auto cell = [&](double t0, double t1, double rho) {
    if (*first_t == kInf) *first_t = t0;
    const double len = std::max(0.0, t1 - t0);
    const double st = sigma_t * rho;
    if (st <= 0) return true;
    const double seg_tau = st * len;
    if (passes_.scattering) {
      // Light scattered towards the camera in this segment, with the
      // light's transmittance from the segment's midpoint, re-evaluated
      // once the ray has moved kScatterStepVoxels voxels from the last
      // evaluation (as vdb_render's shadow step).
      const double mid = t0 + 0.5 * len;
      if (mid >= next_light_t) {
        const glm::dvec3 p_g = gr.origin + mid * gr.dir;
        const glm::dvec3 p_w = xf_.GridToWorld(p_g);
        light_in = glm::dvec3(0.0);
        // With LOD, the step grows with the cone, and the light's rays carry it on.
        const double width = cone != nullptr ? std::max(1.0, cone->Width(mid)) : 1.0;
        next_light_t = mid + scatter_step * width;
        const Cone light_cone = cone != nullptr ? SecondaryCone(*cone, mid) : Cone{};
        ForEachLight(scene_.lights, p_w,
                     [&](const Light& l, const glm::dvec3& to_light, double dist) {
                       double tl = l.shadows ? Transmittance(SpawnRay(p_g, to_light), dist, cx,
                                                             cone != nullptr ? &light_cone : nullptr)
                                             : 1.0;
                       light_in += l.color * l.intensity * tl;
                     });
      }
      scattered += std::exp(-tau) * (1.0 - std::exp(-seg_tau)) * (v.scattering / sigma_t) *
                   v.color * light_in;
    }
    tau += seg_tau;
    return !cx.failed() && std::exp(-tau) >= kMinTransmittance;
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

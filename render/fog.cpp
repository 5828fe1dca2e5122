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

double Renderer::Transmittance(const Ray& gr, double t_max, Ctx& cx) const {
  ++cx.c->rays[kRayVolume];
  const double sigma_t = scene_.volume.absorption + scene_.volume.scattering;
  const bool has_density = volume_->meta().has_density;
  double tau = 0.0;
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
bool Renderer::Density(const Hit& h, Ctx& cx, double* rho) const {
  ++cx.c->attribute_lookups;
  auto a = volume_->HitAttributes(h);  // called by visitors: h's brick is pinned
  if (!a.ok()) {
    cx.Fail(a.status());
    return false;
  }
  *rho = a->density;
  return true;
}

glm::dvec3 Renderer::Fog(const Ray& gr, Ctx& cx, double* transmittance, double* first_t) const {
  const VolumeMedium& v = scene_.volume;
  const double sigma_t = v.absorption + v.scattering;
  const bool has_density = volume_->meta().has_density;
  double tau = 0.0;
  glm::dvec3 scattered(0.0), light_in(0.0);
  double next_light_t = -kInf;
  // Ray parameter per voxel along this ray (t is in world units).
  const double scatter_step = kScatterStepVoxels * volume_->meta().voxel_size;
  *first_t = kInf;
  Status s = cx.tracer->Traverse(
      gr,
      [&](const Hit& h) {
        if (*first_t == kInf) *first_t = h.t;
        const double t1 = VoxelExitT(gr, h.voxel);
        const double len = std::max(0.0, t1 - h.t);
        double rho = 1.0;
        if (has_density && !Density(h, cx, &rho)) return false;
        const double st = sigma_t * rho;
        if (st <= 0) return true;
        const double seg_tau = st * len;
        if (passes_.scattering) {
          // Light scattered towards the camera in this segment, with the
          // light's transmittance from the segment's midpoint, re-evaluated
          // once the ray has moved kScatterStepVoxels voxels from the last
          // evaluation (as vdb_render's shadow step).
          const double mid = h.t + 0.5 * len;
          if (mid >= next_light_t) {
            const glm::dvec3 p_g = gr.origin + mid * gr.dir;
            const glm::dvec3 p_w = xf_.GridToWorld(p_g);
            light_in = glm::dvec3(0.0);
            next_light_t = mid + scatter_step;
            ForEachLight(scene_.lights, p_w,
                         [&](const Light& l, const glm::dvec3& to_light, double dist) {
                           double tl =
                               l.shadows ? Transmittance(SpawnRay(p_g, to_light), dist, cx) : 1.0;
                           light_in += l.color * l.intensity * tl;
                         });
          }
          scattered += std::exp(-tau) * (1.0 - std::exp(-seg_tau)) * (v.scattering / sigma_t) *
                       v.color * light_in;
        }
        tau += seg_tau;
        return !cx.failed() && std::exp(-tau) >= kMinTransmittance;
      },
      &cx.c->trace);
  if (!s.ok()) cx.Fail(s);
  *transmittance = std::exp(-tau);
  return scattered;
}

}  // namespace vox

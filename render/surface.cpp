// The Renderer's surfaces: secondary rays, hits, surface shading (local
// lighting with shadows, reflection) and refraction through an object.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "render/internal/tracing.h"
#include "render/renderer.h"

namespace vox {

using render_internal::ForEachLight;
using render_internal::kInf;
using render_internal::kSurfaceOffsetVoxels;
using render_internal::OccupiedRun;

Ray Renderer::SpawnRay(const glm::dvec3& p_g, const glm::dvec3& dir_w,
                       const glm::dvec3* lift_normal, double lift_scale) const {
  glm::dvec3 origin = p_g;
  if (lift_normal != nullptr)
    origin = p_g + xf_.world_to_grid_linear *
                       (*lift_normal *
                        (kSurfaceOffsetVoxels * lift_scale * volume_->meta().voxel_size));
  return Ray{origin, xf_.world_to_grid_linear * dir_w};
}

bool Renderer::FindHit(const Ray& gr, bool skip_start_run, TraceContext& cx, Hit* hit,
                       VoxelAttributes* attrs, const StartPlane* start) const {
  OccupiedRun run(eps_t_, skip_start_run);
  bool found = false;
  Status s = cx.tracer->Traverse(
      gr,
      [&](const Hit& h) {
        if (run.Continues(h)) {
          run.Extend(gr, h);
          return true;
        }
        *hit = h;
        found = true;
        if (attrs != nullptr) {
          // While the traversal still pins the hit's brick: read from it.
          ++cx.c->attribute_lookups;
          StatusOr<VoxelAttributes> a = volume_->HitAttributes(h);
          if (!a.ok()) {
            cx.Fail(a.status());
            found = false;
          } else {
            *attrs = *a;
          }
        }
        return false;
      },
      &cx.c->trace, start);
  if (!s.ok()) {
    cx.Fail(s);
    return false;
  }
  if (found) ++cx.c->trace.hits;
  return found;
}

bool Renderer::Occluded(const Ray& gr, double t_max, TraceContext& cx) const {
  ++cx.c->rays[kRayShadow];
  Hit h;
  if (!FindHit(gr, /*skip_start_run=*/true, cx, &h)) return false;
  return h.t < t_max;
}

glm::dvec3 Renderer::WorldNormal(const Ray& gr, const Hit& h, const VoxelAttributes& a,
                                 int level) const {
  glm::dvec3 n(a.normal);
  if (!(glm::dot(n, n) > 0)) {
    // No stored normal: the face the ray entered through.
    int axis = 0;
    double best = -kInf;
    for (int ax = 0; ax < 3; ++ax) {
      if (gr.dir[ax] == 0) continue;
      double face = std::ldexp(double(h.voxel[ax]) + (gr.dir[ax] > 0 ? 0.0 : 1.0), level);
      double t = (face - gr.origin[ax]) / gr.dir[ax];
      if (t > best) {
        best = t;
        axis = ax;
      }
    }
    n = glm::dvec3(0.0);
    n[axis] = gr.dir[axis] > 0 ? -1.0 : 1.0;
  }
  glm::dvec3 w = xf_.normal_to_world * n;
  double len = glm::length(w);
  return len > 0 ? w / len : glm::dvec3(0.0, 1.0, 0.0);
}

glm::dvec3 Renderer::ShadeSurface(const Ray& gr, const glm::dvec3& dir_w, const Hit& h,
                                  const VoxelAttributes& attrs, int depth, TraceContext& cx,
                                  glm::dvec3* normal_out, const LodRay* lod) const {
  const glm::dvec3 origin_w = xf_.GridToWorld(gr.origin);
  const glm::dvec3 p_w = origin_w + h.t * dir_w;
  const glm::dvec3 p_g = gr.origin + h.t * gr.dir;
  // A coarse cell's secondary rays carry the cone on, lifted by its size.
  if (lod != nullptr && lod->level == 0) lod = nullptr;
  const double lift = lod != nullptr ? std::ldexp(1.0, lod->level) : 1.0;
  const Cone cone = lod != nullptr ? SecondaryCone(lod->cone, h.t) : Cone{};
  glm::dvec3 n(0.0);  // unused without lights, reflection, refraction and the normal layer
  if (needs_normal_) {
    const glm::dvec3 n_out = WorldNormal(gr, h, attrs, lod != nullptr ? lod->level : 0);
    n = glm::dot(n_out, dir_w) > 0 ? -n_out : n_out;  // facing the viewer
  }
  if (normal_out) *normal_out = n;
  const Material& m = scene_.MaterialAt(p_w);
  const glm::dvec3 base = volume_->meta().has_color ? glm::dvec3(attrs.color) : m.color;
  const double k_local = 1.0 - m.reflect - m.transmit;
  glm::dvec3 color(0.0);
  if (k_local > 0) {
    glm::dvec3 local = base * scene_.ambient;
    ForEachLight(scene_.lights, p_w, [&](const Light& l, const glm::dvec3& to_light, double dist) {
      double ndl = glm::dot(n, to_light);
      if (ndl <= 0) return;
      if (passes_.shadows && l.shadows &&
          (lod != nullptr ? OccludedLod(SpawnRay(p_g, to_light, &n, lift), dist, cone, cx)
                          : Occluded(SpawnRay(p_g, to_light, &n), dist, cx)))
        return;
      glm::dvec3 li = l.color * l.intensity;
      glm::dvec3 hv = to_light - dir_w;
      double hl = glm::length(hv);
      double spec = 0;
      if (m.specular > 0 && hl > 0)
        spec = m.specular * std::pow(std::max(0.0, glm::dot(n, hv / hl)), m.shininess);
      local += li * (base * (m.diffuse * ndl) + glm::dvec3(spec));
    });
    color += k_local * local;
  }
  if (depth < scene_.max_depth) {
    if (passes_.reflection && m.reflect > 0) {
      glm::dvec3 r = glm::reflect(dir_w, n);
      color += m.reflect *
               (lod != nullptr
                    ? RadianceLod(SpawnRay(p_g, r, &n, lift), r, depth + 1, kRayReflection, cone, cx)
                    : Radiance(SpawnRay(p_g, r, &n), r, depth + 1, kRayReflection, cx));
    }
    if (passes_.refraction && m.transmit > 0) {
      glm::dvec3 t = glm::refract(dir_w, n, 1.0 / m.ior);
      if (glm::dot(t, t) > 0) {
        const glm::dvec3 td = glm::normalize(t);
        color += m.transmit * base * Refract(SpawnRay(p_g, td), p_w, td, depth + 1, cx);
      } else {
        glm::dvec3 r = glm::reflect(dir_w, n);
        color += m.transmit * Radiance(SpawnRay(p_g, r, &n), r, depth + 1, kRayReflection, cx);
      }
    }
  }
  return color;
}

glm::dvec3 Renderer::Radiance(const Ray& gr, const glm::dvec3& dir_w, int depth, int kind,
                              TraceContext& cx) const {
  ++cx.c->rays[kind];
  Hit h;
  VoxelAttributes a;
  if (!FindHit(gr, /*skip_start_run=*/true, cx, &h, SurfaceAttrs(&a)))
    return cx.failed() ? glm::dvec3(0.0) : Background(dir_w);
  return ShadeSurface(gr, dir_w, h, a, depth, cx, nullptr);
}

glm::dvec3 Renderer::Refract(const Ray& gr, const glm::dvec3& origin_w, const glm::dvec3& dir,
                             int depth, TraceContext& cx) const {
  ++cx.c->rays[kRayRefraction];
  OccupiedRun run(eps_t_, /*started=*/false);
  bool exited = false;
  Hit last;
  glm::dvec3 exit_n(0.0);
  auto normal_of = [&](const Hit& h, glm::dvec3* n) {
    ++cx.c->attribute_lookups;
    auto a = volume_->Attributes(h.brick, h.payload);
    if (!a.ok()) {
      cx.Fail(a.status());
      return false;
    }
    *n = WorldNormal(gr, h, *a);
    return true;
  };
  Status s = cx.tracer->Traverse(
      gr,
      [&](const Hit& h) {
        if (run.EndedBefore(h)) {
          glm::dvec3 n;
          if (!normal_of(last, &n)) return false;
          if (glm::dot(n, dir) > 0) {  // the run we just left was a back surface
            exited = true;
            exit_n = n;
            return false;
          }
        }
        run.Extend(gr, h);
        last = h;
        return true;
      },
      &cx.c->trace);
  if (!s.ok()) cx.Fail(s);
  if (cx.failed()) return glm::dvec3(0.0);
  if (!exited) {
    if (!run.active()) return Background(dir);  // nothing inside: pass straight through
    if (!normal_of(last, &exit_n)) return glm::dvec3(0.0);
  }
  if (glm::dot(exit_n, dir) < 0) exit_n = -exit_n;
  const double run_end = run.end();
  const glm::dvec3 q_g = gr.origin + run_end * gr.dir;
  const glm::dvec3 q_w = origin_w + run_end * dir;
  const Material& m = scene_.MaterialAt(q_w);
  glm::dvec3 out = glm::refract(dir, -exit_n, m.ior);
  if (glm::dot(out, out) > 0) {
    const glm::dvec3 od = glm::normalize(out);
    return Radiance(SpawnRay(q_g, od, &exit_n), od, depth, kRayRefraction, cx);
  }
  // Total internal reflection: another pass inside, if the depth allows.
  if (depth >= scene_.max_depth) return glm::dvec3(0.0);
  const glm::dvec3 r = glm::reflect(dir, -exit_n);
  return Refract(SpawnRay(q_g, r), q_w, r, depth + 1, cx);
}

}  // namespace vox

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

namespace {

// The stored normal of grid voxel v, found from the root of `view` (bricks
// through `bricks`; `last` keeps the last brick fetched, for the next call).
// False: v is unoccupied or outside the grid.
StatusOr<bool> VoxelNormal(const OctreeView& view, BrickSource* bricks, Volume* volume,
                           const glm::i64vec3& v, BrickView* last, uint32_t* last_id,
                           glm::dvec3* n) {
  const int64_t side = int64_t(1) << view.levels;
  if (v.x < 0 || v.y < 0 || v.z < 0 || v.x >= side || v.y >= side || v.z >= side ||
      view.top_cells == 0)
    return false;
  const CompactCell* pool = view.top;
  uint32_t cell = 0, brick = kNoBrick;
  const void* data = nullptr;
  for (int depth = 0; depth < view.levels; ++depth) {
    const int shift = view.levels - depth - 1;
    const unsigned digit = unsigned((v.x >> shift) & 1) | unsigned(((v.y >> shift) & 1) << 1) |
                           unsigned(((v.z >> shift) & 1) << 2);
    const ChildRef ref = ChildOf(pool[cell], digit, depth, view);
    switch (ref.kind) {
      case ChildRef::kEmpty:
        return false;
      case ChildRef::kCell:
        cell = ref.index;
        break;
      case ChildRef::kBrick:
        if (bricks == nullptr) return CorruptionError("a brick reference without bricks");
        if (*last_id != ref.index || last->cells == nullptr) {
          VOX_ASSIGN_OR_RETURN(*last, bricks->FetchBrick(ref.index));
          *last_id = ref.index;
        }
        pool = last->cells;
        data = last->data;
        cell = 0;
        brick = ref.index;
        break;
      case ChildRef::kPayload: {
        Hit h;
        h.voxel = v;
        h.brick = brick;
        h.payload = ref.index;
        h.brick_data = data;
        VOX_ASSIGN_OR_RETURN(VoxelAttributes a, volume->HitAttributes(h));
        *n = glm::dvec3(a.normal);
        return glm::dot(*n, *n) > 0;
      }
    }
  }
  return false;
}

// `n` facing the ray's origin (dot(n, dir) <= 0): one facing away is
// mirrored across the plane perpendicular to dir. A normal just past the
// silhouette stays nearly perpendicular to the ray, on its side towards the
// lights; negating it instead would turn it into the surface, away from
// every light in front (a black pixel one voxel off the silhouette).
glm::dvec3 FacingRay(const glm::dvec3& n, const glm::dvec3& dir) {
  const double d = glm::dot(n, dir);
  if (!(d > 0)) return n;
  const glm::dvec3 m = n - 2.0 * d * dir;
  const double len = glm::length(m);
  return len > 0 ? m / len : -n;
}

}  // namespace

glm::dvec3 Renderer::SmoothNormal(const glm::dvec3& p_g, const Hit& h, const VoxelAttributes& a,
                                  TraceContext& cx) const {
  const glm::dvec3 own(a.normal);
  // The hit point, kept in its voxel (the ray's entry point may round outside it).
  const glm::dvec3 lo(h.voxel), p = glm::clamp(p_g, lo, lo + 1.0);
  // Quadratic B-spline weights over the 3x3x3 voxels around the one whose
  // centre is nearest: per axis 0.5 (0.5 - f)^2, 0.75 - f^2, 0.5 (0.5 + f)^2
  // with f in [-0.5, 0.5] the point's offset from that centre.
  const glm::dvec3 q = p - 0.5;
  const glm::dvec3 c = glm::floor(q + 0.5), f = q - c;
  const glm::i64vec3 centre(c);
  double wt[3][3];
  for (int a = 0; a < 3; ++a) {
    wt[a][0] = 0.5 * (0.5 - f[a]) * (0.5 - f[a]);
    wt[a][1] = 0.75 - f[a] * f[a];
    wt[a][2] = 0.5 * (0.5 + f[a]) * (0.5 + f[a]);
  }
  const OctreeView view = volume_->view();
  BrickSource* bricks = cx.bricks != nullptr ? cx.bricks : view.bricks;
  BrickView last;
  uint32_t last_id = kNoBrick;
  glm::dvec3 sum(0.0);
  for (int k = 0; k < 27; ++k) {
    const glm::i64vec3 o(k % 3, (k / 3) % 3, k / 9);
    const glm::i64vec3 v = centre + o - glm::i64vec3(1);
    const double w = wt[0][o.x] * wt[1][o.y] * wt[2][o.z];
    if (!(w > 0)) continue;
    glm::dvec3 n;
    if (v == h.voxel) {
      n = own;
    } else {
      ++cx.c->attribute_lookups;
      StatusOr<bool> found = VoxelNormal(view, bricks, volume_, v, &last, &last_id, &n);
      if (!found.ok()) {
        cx.Fail(found.status());
        return own;
      }
      if (!*found) continue;
    }
    sum += w * n;
  }
  return glm::dot(sum, sum) > 1e-12 ? sum : own;
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
    VoxelAttributes a = attrs;
    if (smooth_normals_ && lod == nullptr && glm::dot(a.normal, a.normal) > 0)
      a.normal = glm::vec3(SmoothNormal(p_g, h, attrs, cx));
    n = FacingRay(WorldNormal(gr, h, a, lod != nullptr ? lod->level : 0), dir_w);
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

#include "render/renderer.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

namespace vox {
namespace {

// The unit direction from world point p to light l and its distance (inf for
// a directional light). False when p is at a point light's position.
bool DirectionToLight(const Light& l, const glm::dvec3& p, glm::dvec3* to_light, double* dist) {
  if (l.type == Light::Type::kDirectional) {
    *to_light = -l.direction;
    *dist = std::numeric_limits<double>::infinity();
    return true;
  }
  *to_light = l.position - p;
  *dist = glm::length(*to_light);
  if (!(*dist > 0)) return false;
  *to_light /= *dist;
  return true;
}

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMinTransmittance = 1e-6;
constexpr double kScatterStepVoxels = 3.0;
// Secondary rays leaving a surface start this many voxels out along its
// normal: a hit point lies within 1.9 voxels below and 0.9 above the true
// surface, and the voxels of the surface within 0.9 above it, so a ray
// lifted by 2.5 voxels clears the surface's own staircase even at grazing
// angles (no shadow or reflection acne). Occluders closer than that to the
// surface cast no shadow.
constexpr double kSurfaceOffsetVoxels = 2.5;

double RadicalInverse2(uint32_t k) {
  k = (k << 16) | (k >> 16);
  k = ((k & 0x55555555u) << 1) | ((k & 0xAAAAAAAAu) >> 1);
  k = ((k & 0x33333333u) << 2) | ((k & 0xCCCCCCCCu) >> 2);
  k = ((k & 0x0F0F0F0Fu) << 4) | ((k & 0xF0F0F0F0u) >> 4);
  k = ((k & 0x00FF00FFu) << 8) | ((k & 0xFF00FF00u) >> 8);
  return double(k) * (1.0 / 4294967296.0);
}

}  // namespace

const char* RayKindName(int kind) {
  static const char* const kNames[kNumRayKinds] = {"primary", "shadow", "reflection", "refraction",
                                                   "volume"};
  return kNames[kind];
}

void RenderCounters::Add(const RenderCounters& o) {
  trace.Add(o.trace);
  for (int k = 0; k < kNumRayKinds; ++k) rays[k] += o.rays[k];
  pixels += o.pixels;
  hit_pixels += o.hit_pixels;
  attribute_lookups += o.attribute_lookups;
}

std::string RenderPasses::ToString() const {
  std::string s = volume ? "volume" : "primary";
  if (!volume && shading) s += "+shading";
  if (shadows) s += "+shadows";
  if (reflection) s += "+reflection";
  if (refraction) s += "+refraction";
  if (scattering) s += "+scattering";
  return s;
}

// A thread's own view of the bricks: the last bricks it fetched, pinned, in a
// direct-mapped table, so a ray entering a brick a neighbouring ray just used
// takes neither the shared cache's lock, hash and LRU nor a reference count:
// the table lends its views to the thread's tracer (BrickSource::lends).
class Renderer::LocalBricks : public BrickSource {
 public:
  // 2^slot_bits pins: they hold bricks alive beyond the shared cache's budget.
  LocalBricks(BrickSource* base, int slot_bits)
      : base_(base), shift_(32 - slot_bits), slots_(size_t(1) << slot_bits) {}

  // Table size for a cache of `capacity` bytes: 256 slots (a 64 x 64 tile's
  // rays enter a few dozen bricks; 256 measured 3-5% faster than 64) at 1 GiB,
  // fewer (down to 16) for smaller caches, so the pins of a thread stay near
  // 1/64 of the budget for bricks of 64 KiB (the benchmark's sphere decodes to
  // 24 KiB per brick).
  static int SlotBits(uint64_t capacity) {
    int bits = 4;
    while (bits < 8 && (uint64_t(1) << (bits + 1)) * (64u << 10) * 64 <= capacity) ++bits;
    return bits;
  }
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    Status error;
    const BrickView* v = LendBrick(id, &error);
    if (v == nullptr) return error;
    return *v;
  }
  bool lends() const override { return true; }
  const BrickView* LendBrick(uint32_t id, Status* error) override {
    Slot& s = slots_[(id * 2654435761u) >> shift_];
    if (s.id == id && s.view.cells != nullptr) return &s.view;
    auto v = base_->FetchBrick(id);
    if (!v.ok()) {
      *error = v.status();
      return nullptr;
    }
    s.id = id;
    s.view = std::move(v).value();
    return &s.view;
  }

 private:
  struct Slot {
    uint32_t id = 0;
    BrickView view;  // cells == nullptr: empty
  };
  BrickSource* base_;
  int shift_;
  std::vector<Slot> slots_;
};

struct Renderer::ThreadState {
  std::unique_ptr<LocalBricks> bricks;
  RenderTracer tracer;
};

std::unique_ptr<Renderer::ThreadState, Renderer::ThreadStateDeleter> Renderer::NewThreadState()
    const {
  std::unique_ptr<ThreadState, ThreadStateDeleter> ts(new ThreadState());
  OctreeView view = volume_->view();
  if (view.bricks != nullptr) {
    const uint64_t capacity = volume_->cache_stats().capacity;
    ts->bricks = std::make_unique<LocalBricks>(
        view.bricks, LocalBricks::SlotBits(capacity > 0 ? capacity : uint64_t(1) << 30));
    view.bricks = ts->bricks.get();
  }
  auto t = RenderTracer::Create(view, tracer_.n1());
  ts->tracer = t.ok() ? *t : tracer_;  // cannot fail: same tree and split as tracer_
  return ts;
}

void Renderer::ThreadStateDeleter::operator()(ThreadState* ts) const { delete ts; }

// Per-call state: the thread's counters and the first error.
struct Renderer::Ctx {
  const RenderTracer* tracer;
  RenderCounters* c;
  Status error;
  bool failed() const { return !error.ok(); }
  void Fail(const Status& s) {
    if (error.ok()) error = s;
  }
};

struct Renderer::Sample {
  glm::dvec3 color{0.0};
  double alpha = 0.0;
  double z = kInf;
  bool hit = false;
  glm::dvec3 normal{0.0};
  glm::i64vec3 voxel{0};
};

StatusOr<std::unique_ptr<Renderer>> Renderer::Create(RenderVolume* volume, const Camera& camera,
                                                     const Scene& scene,
                                                     const RenderOptions& options) {
  const StoreMeta& meta = volume->meta();
  OctreeView view = volume->view();
  int n1 = options.n1 > 0 ? options.n1 : DefaultFirstStepLevels(view.levels);
  VOX_ASSIGN_OR_RETURN(RenderTracer tracer, RenderTracer::Create(view, n1));
  VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(meta));
  Camera cam = camera;
  VOX_RETURN_IF_ERROR(cam.Finalize("camera"));
  auto r = std::unique_ptr<Renderer>(new Renderer(volume, cam, scene, options, tracer, xf));
  Scene& s = r->scene_;
  if (s.default_lights) {
    // A key light above, behind and to the left of the camera.
    glm::dvec3 to_light =
        glm::normalize(-0.55 * cam.forward() + 0.75 * cam.true_up() - 0.45 * cam.right());
    Light key;
    key.type = Light::Type::kDirectional;
    key.direction = -to_light;
    key.color = glm::dvec3(1.0);
    key.intensity = 0.9;
    key.shadows = true;
    s.lights = {key};
    s.default_lights = false;
  }
  r->fog_ = meta.grid_class == GridClass::kFogVolume;
  bool any_light = false, any_shadow = false;
  for (const Light& l : s.lights) {
    if (l.intensity <= 0) continue;
    any_light = true;
    any_shadow = any_shadow || l.shadows;
  }
  double max_reflect = s.material.reflect, max_transmit = s.material.transmit;
  for (const MaterialRegion& reg : s.regions) {
    max_reflect = std::max(max_reflect, reg.material.reflect);
    max_transmit = std::max(max_transmit, reg.material.transmit);
  }
  RenderPasses& p = r->passes_;
  p.volume = r->fog_;
  p.shading = !r->fog_;
  p.shadows = !r->fog_ && any_shadow;
  p.reflection = !r->fog_ && s.max_depth > 0 && max_reflect > 0;
  p.refraction = !r->fog_ && s.max_depth > 0 && max_transmit > 0;
  p.scattering = r->fog_ && any_light && s.volume.scattering > 0;
  r->needs_attributes_ =
      meta.has_color || any_light || p.reflection || p.refraction || options.layers.normal;
  r->eps_t_ = 1e-7 * std::max(meta.voxel_size, 1e-300);
  return r;
}

std::string Renderer::SplitString() const {
  return tracer_.single_step() ? std::to_string(tracer_.n1()) + " (single step)"
                               : std::to_string(tracer_.n1()) + "+" + std::to_string(tracer_.n2());
}

glm::dvec3 Renderer::OffsetAlong(const glm::dvec3& p_g, const glm::dvec3& n_world) const {
  return p_g +
         xf_.world_to_grid_linear * (n_world * (kSurfaceOffsetVoxels * volume_->meta().voxel_size));
}

Ray Renderer::ToGrid(const glm::dvec3& origin_w, const glm::dvec3& dir_w) const {
  return Ray{xf_.WorldToGrid(origin_w), xf_.world_to_grid_linear * dir_w};
}

glm::dvec3 Renderer::Background(const glm::dvec3& dir) const {
  double u = 0.5 * (glm::dot(dir, camera_.true_up()) + 1.0);
  return glm::mix(scene_.background_bottom, scene_.background_top, std::clamp(u, 0.0, 1.0));
}

bool Renderer::FindHit(const Ray& gr, bool skip_start_run, Ctx& cx, Hit* hit,
                       VoxelAttributes* attrs) const {
  bool in_run = skip_start_run, found = false;
  double run_end = 0.0;
  const double eps = eps_t_;
  Status s = cx.tracer->Traverse(
      gr,
      [&](const Hit& h) {
        if (in_run) {
          if (h.t <= run_end + eps * (1.0 + run_end)) {
            run_end = VoxelExitT(gr, h.voxel);
            return true;
          }
          in_run = false;
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
      &cx.c->trace);
  if (!s.ok()) {
    cx.Fail(s);
    return false;
  }
  if (found) ++cx.c->trace.hits;
  return found;
}

bool Renderer::Occluded(const glm::dvec3& origin_g, const glm::dvec3& dir_w, double t_max,
                        Ctx& cx) const {
  Ray gr{origin_g, xf_.world_to_grid_linear * dir_w};
  ++cx.c->rays[kRayShadow];
  Hit h;
  if (!FindHit(gr, /*skip_start_run=*/true, cx, &h)) return false;
  return h.t < t_max;
}

glm::dvec3 Renderer::WorldNormal(const Ray& gr, const Hit& h, const VoxelAttributes& a) const {
  glm::dvec3 n(a.normal);
  if (!(glm::dot(n, n) > 0)) {
    // No stored normal: the face the ray entered through.
    int axis = 0;
    double best = -kInf;
    for (int ax = 0; ax < 3; ++ax) {
      if (gr.dir[ax] == 0) continue;
      double face = double(h.voxel[ax]) + (gr.dir[ax] > 0 ? 0.0 : 1.0);
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
                                  const VoxelAttributes& attrs, int depth, Ctx& cx,
                                  glm::dvec3* normal_out) const {
  const glm::dvec3 origin_w = xf_.GridToWorld(gr.origin);
  const glm::dvec3 p_w = origin_w + h.t * dir_w;
  const glm::dvec3 p_g = gr.origin + h.t * gr.dir;
  const glm::dvec3 n_out = WorldNormal(gr, h, attrs);
  const glm::dvec3 n = glm::dot(n_out, dir_w) > 0 ? -n_out : n_out;  // facing the viewer
  if (normal_out) *normal_out = n;
  const glm::dvec3 p_off = OffsetAlong(p_g, n);
  const Material& m = scene_.MaterialAt(p_w);
  const glm::dvec3 base = volume_->meta().has_color ? glm::dvec3(attrs.color) : m.color;
  const double k_local = 1.0 - m.reflect - m.transmit;
  glm::dvec3 color(0.0);
  if (k_local > 0) {
    glm::dvec3 local = base * scene_.ambient;
    for (const Light& l : scene_.lights) {
      if (l.intensity <= 0) continue;
      glm::dvec3 to_light;
      double dist = kInf;
      if (!DirectionToLight(l, p_w, &to_light, &dist)) continue;
      double ndl = glm::dot(n, to_light);
      if (ndl <= 0) continue;
      if (passes_.shadows && l.shadows && Occluded(p_off, to_light, dist, cx)) continue;
      glm::dvec3 li = l.color * l.intensity;
      glm::dvec3 hv = to_light - dir_w;
      double hl = glm::length(hv);
      double spec = 0;
      if (m.specular > 0 && hl > 0)
        spec = m.specular * std::pow(std::max(0.0, glm::dot(n, hv / hl)), m.shininess);
      local += li * (base * (m.diffuse * ndl) + glm::dvec3(spec));
    }
    color += k_local * local;
  }
  if (depth < scene_.max_depth) {
    if (passes_.reflection && m.reflect > 0) {
      glm::dvec3 r = glm::reflect(dir_w, n);
      color += m.reflect * Radiance(p_off, p_w, r, depth + 1, kRayReflection, cx);
    }
    if (passes_.refraction && m.transmit > 0) {
      glm::dvec3 t = glm::refract(dir_w, n, 1.0 / m.ior);
      if (glm::dot(t, t) > 0) {
        color += m.transmit * base * Refract(p_g, p_w, glm::normalize(t), depth + 1, cx);
      } else {
        color += m.transmit *
                 Radiance(p_off, p_w, glm::reflect(dir_w, n), depth + 1, kRayReflection, cx);
      }
    }
  }
  return color;
}

glm::dvec3 Renderer::Radiance(const glm::dvec3& origin_g, const glm::dvec3& origin_w,
                              const glm::dvec3& dir, int depth, int kind, Ctx& cx) const {
  ++cx.c->rays[kind];
  Ray gr{origin_g, xf_.world_to_grid_linear * dir};
  (void)origin_w;
  Hit h;
  VoxelAttributes a;
  if (!FindHit(gr, /*skip_start_run=*/true, cx, &h, SurfaceAttrs(&a)))
    return cx.failed() ? glm::dvec3(0.0) : Background(dir);
  return ShadeSurface(gr, dir, h, a, depth, cx, nullptr);
}

glm::dvec3 Renderer::Refract(const glm::dvec3& origin_g, const glm::dvec3& origin_w,
                             const glm::dvec3& dir, int depth, Ctx& cx) const {
  ++cx.c->rays[kRayRefraction];
  Ray gr{origin_g, xf_.world_to_grid_linear * dir};
  bool have_run = false, exited = false;
  double run_end = 0.0;
  Hit last;
  glm::dvec3 exit_n(0.0);
  const double eps = eps_t_;
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
        if (have_run && h.t > run_end + eps * (1.0 + run_end)) {
          glm::dvec3 n;
          if (!normal_of(last, &n)) return false;
          if (glm::dot(n, dir) > 0) {  // the run we just left was a back surface
            exited = true;
            exit_n = n;
            return false;
          }
        }
        have_run = true;
        run_end = VoxelExitT(gr, h.voxel);
        last = h;
        return true;
      },
      &cx.c->trace);
  if (!s.ok()) cx.Fail(s);
  if (cx.failed()) return glm::dvec3(0.0);
  if (!exited) {
    if (!have_run) return Background(dir);  // nothing inside: pass straight through
    if (!normal_of(last, &exit_n)) return glm::dvec3(0.0);
  }
  if (glm::dot(exit_n, dir) < 0) exit_n = -exit_n;
  const glm::dvec3 q_g = gr.origin + run_end * gr.dir;
  const glm::dvec3 q_w = origin_w + run_end * dir;
  const Material& m = scene_.MaterialAt(q_w);
  glm::dvec3 out = glm::refract(dir, -exit_n, m.ior);
  if (glm::dot(out, out) > 0) {
    ++cx.c->rays[kRayRefraction];
    Ray og{OffsetAlong(q_g, exit_n), xf_.world_to_grid_linear * glm::normalize(out)};
    glm::dvec3 od = glm::normalize(out);
    Hit h;
    VoxelAttributes a;
    if (!FindHit(og, /*skip_start_run=*/true, cx, &h, SurfaceAttrs(&a)))
      return cx.failed() ? glm::dvec3(0.0) : Background(od);
    return ShadeSurface(og, od, h, a, depth, cx, nullptr);
  }
  // Total internal reflection: another pass inside, if the depth allows.
  if (depth >= scene_.max_depth) return glm::dvec3(0.0);
  return Refract(q_g, q_w, glm::reflect(dir, -exit_n), depth + 1, cx);
}

double Renderer::Transmittance(const glm::dvec3& origin_g, const glm::dvec3& dir_w, double t_max,
                               Ctx& cx) const {
  ++cx.c->rays[kRayVolume];
  Ray gr{origin_g, xf_.world_to_grid_linear * dir_w};
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

glm::dvec3 Renderer::Fog(const Ray& gr, const glm::dvec3& dir_w, Ctx& cx, double* transmittance,
                         double* first_t) const {
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
            glm::dvec3& in = light_in;
            in = glm::dvec3(0.0);
            next_light_t = mid + scatter_step;
            for (const Light& l : scene_.lights) {
              if (l.intensity <= 0) continue;
              glm::dvec3 to_light;
              double dist = kInf;
              if (!DirectionToLight(l, p_w, &to_light, &dist)) continue;
              double tl = l.shadows ? Transmittance(p_g, to_light, dist, cx) : 1.0;
              in += l.color * l.intensity * tl;
            }
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
  (void)dir_w;
  return scattered;
}

void Renderer::ShadePixel(double x, double y, Ctx& cx, Sample* out) const {
  const WorldRay wr = camera_.PixelRay(x, y);
  const Ray gr = ToGrid(wr.origin, wr.dir);
  ++cx.c->rays[kRayPrimary];
  if (fog_) {
    double T = 1.0, first_t = kInf;
    glm::dvec3 l = Fog(gr, wr.dir, cx, &T, &first_t);
    out->color = l + T * Background(wr.dir);
    out->alpha = 1.0 - T;
    out->z = first_t;
    out->hit = first_t < kInf;
    return;
  }
  Hit h;
  VoxelAttributes a;
  if (!FindHit(gr, /*skip_start_run=*/false, cx, &h, SurfaceAttrs(&a))) {
    if (!cx.failed()) out->color = Background(wr.dir);
    return;
  }
  out->hit = true;
  out->alpha = 1.0;
  out->z = h.t;
  out->voxel = h.voxel + volume_->meta().origin;
  out->color = ShadeSurface(gr, wr.dir, h, a, 0, cx, &out->normal);
}

Status Renderer::RenderTile(const TileRect& rect, TileBuffer* buf, RenderCounters* counters,
                            ThreadState* ts) const {
  Ctx cx{ts ? &ts->tracer : &tracer_, counters, OkStatus()};
  const int spp = scene_.samples_per_pixel;
  const ImageLayers& layers = options_.layers;
  const float inf = std::numeric_limits<float>::infinity();
  for (int py = 0; py < rect.h; ++py) {
    for (int px = 0; px < rect.w; ++px) {
      const int ix = rect.x0 + px, iy = rect.y0 + py;
      glm::dvec3 color(0.0), normal(0.0);
      double alpha = 0.0, z = kInf;
      glm::i64vec3 voxel(0);
      bool any_hit = false;
      for (int k = 0; k < spp; ++k) {
        double ox = 0.5, oy = 0.5;
        if (spp > 1) {
          ox = (k + 0.5) / spp;
          oy = RadicalInverse2(uint32_t(k) + 1u);
        }
        Sample s;
        ShadePixel(ix + ox, iy + oy, cx, &s);
        if (cx.failed()) return cx.error;
        color += s.color;
        alpha += s.alpha;
        if (s.hit && s.z < z) {
          z = s.z;
          normal = s.normal;
          voxel = s.voxel;
        }
        any_hit = any_hit || s.hit;
      }
      ++counters->pixels;
      if (any_hit) ++counters->hit_pixels;
      const double inv = 1.0 / spp;
      *buf->at(kChR, px, py) = float(color.r * inv);
      *buf->at(kChG, px, py) = float(color.g * inv);
      *buf->at(kChB, px, py) = float(color.b * inv);
      *buf->at(kChA, px, py) = float(alpha * inv);
      *buf->at(kChZ, px, py) = z < kInf ? float(z) : inf;
      if (layers.normal) {
        *buf->at(kChNx, px, py) = float(normal.x);
        *buf->at(kChNy, px, py) = float(normal.y);
        *buf->at(kChNz, px, py) = float(normal.z);
      }
      if (layers.voxel) {
        *buf->at(kChVi, px, py) = any_hit ? float(voxel.x) : 0.0f;
        *buf->at(kChVj, px, py) = any_hit ? float(voxel.y) : 0.0f;
        *buf->at(kChVk, px, py) = any_hit ? float(voxel.z) : 0.0f;
      }
    }
  }
  return OkStatus();
}

}  // namespace vox

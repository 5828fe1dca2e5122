// The Renderer's set-up (passes, default lights, per-thread state) and its
// primary rays; the tile loop is in tile_render.cpp, surfaces in
// surface.cpp, fog in fog.cpp.
#include "render/renderer.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "render/internal/fog_light.h"
#include "render/internal/tracing.h"
#include "storage/brick_table.h"

namespace vox {
namespace {

using render_internal::kInf;

// Notes the first kRecordedBricks bricks a traversal enters, reading none:
// each looks empty (the ray goes on through it), and the next ends the ray
// (an error without a message: no allocation). Call Restart per ray.
class RecordingSource : public BrickSource {
 public:
  RecordingSource(std::vector<uint32_t>* ids, int per_ray) : ids_(ids), per_ray_(per_ray) {}
  void Restart() { entered_ = 0; }
  StatusOr<BrickView> FetchBrick(uint32_t id) override {
    if (entered_++ == per_ray_) return NotFoundError(std::string());
    ids_->push_back(id);
    static const CompactCell kEmpty{};  // mask 0: an empty root
    return BrickView{&kEmpty, 1, nullptr, nullptr};
  }

 private:
  std::vector<uint32_t>* ids_;
  int per_ray_;
  int entered_ = 0;
};

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
  deferred_pixels += o.deferred_pixels;
  lod.Add(o.lod);
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

std::unique_ptr<Renderer::ThreadState, Renderer::ThreadStateDeleter> Renderer::NewThreadState()
    const {
  std::unique_ptr<ThreadState, ThreadStateDeleter> ts(new ThreadState());
  OctreeView view = volume_->view();
  int bits = options_.table_slot_bits;
  if (bits < 0) {
    const uint64_t capacity = volume_->cache_stats().capacity;
    bits = LendingBrickTable::SlotBits(capacity > 0 ? capacity : uint64_t(1) << 30);
  }
  if (lod_) {
    // The pins are shared: half for the base's table, half for the levels'.
    bits = std::max(0, bits - 1);
    ts->lod = lod_->NewThread(bits);
  }
  if (view.bricks != nullptr) {
    ts->bricks = std::make_unique<LendingBrickTable>(view.bricks, bits);
    view.bricks = ts->bricks.get();
  }
  auto t = RenderTracer::Create(view, tracer_.n1());
  ts->tracer = t.ok() ? *t : tracer_;  // cannot fail: same tree and split as tracer_
  ApplyOccupiedBox(&ts->tracer);
  return ts;
}

void Renderer::ApplyOccupiedBox(RenderTracer* t) const {
  if (options_.clip_to_occupied) ClipToOccupiedBox(volume_->meta(), t);
}

void Renderer::ThreadStateDeleter::operator()(ThreadState* ts) const { delete ts; }

StatusOr<std::unique_ptr<Renderer>> Renderer::Create(Volume* volume, const Camera& camera,
                                                     const Scene& scene,
                                                     const RenderOptions& options) {
  const StoreMeta& meta = volume->meta();
  OctreeView view = volume->view();
  // Fog walks long runs of occupied voxels: larger second-step cells.
  const bool fog = meta.grid_class == GridClass::kFogVolume;
  int n1 = options.n1 > 0                   ? options.n1
           : fog ? render_internal::FogFirstStepLevels(view.levels)
                 : DefaultFirstStepLevels(view.levels);
  VOX_ASSIGN_OR_RETURN(RenderTracer tracer, RenderTracer::Create(view, n1));
  VOX_ASSIGN_OR_RETURN(GridTransform xf, GridTransform::FromMeta(meta));
  if (!camera.finalized())
    return InvalidArgumentError("camera: not finalised (Camera::Finalize checks it and computes its frame)");
  if (options.beam && (options.beam_block < 1 || options.beam_block > 4096))
    return InvalidArgumentError("beam block " + std::to_string(options.beam_block) +
                                ": must be in 1..4096 pixels");
  const Camera& cam = camera;
  auto r = std::unique_ptr<Renderer>(new Renderer(volume, cam, scene, options, tracer, xf));
  r->ApplyOccupiedBox(&r->tracer_);
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
  r->fog_model_ = FogModel(s.volume);
  if (r->fog_ && r->fog_model_.uses_temperature() && !meta.has_temperature)
    return InvalidArgumentError(
        "scene: volume.blackbody needs a temperature per voxel, and the store of grid '" +
        meta.grid_name + "' has none (ingest with vox-ingest --temperature GRID)");
  r->grey_fog_ = r->fog_model_.grey();
  r->lattice_level_ = std::ilogb(s.volume.light_step / render_internal::kLatticeSampleSpacings);
  for (const Light& l : s.lights)
    if (l.intensity > 0)
      r->grey_fog_ = r->grey_fog_ && l.color.x == l.color.y && l.color.x == l.color.z;
  bool any_light = false, any_shadow = false;
  for (const Light& l : s.lights) {
    if (l.intensity <= 0) continue;
    any_light = true;
    any_shadow = any_shadow || l.shadows;
  }
  double max_reflect = s.material.reflect;
  for (const MaterialRegion& reg : s.regions) {
    max_reflect = std::max(max_reflect, reg.material.reflect);
  }
  RenderPasses& p = r->passes_;
  p.volume = r->fog_;
  p.shading = !r->fog_;
  p.shadows = !r->fog_ && any_shadow;
  p.reflection = !r->fog_ && s.max_depth > 0 && max_reflect > 0;
  p.refraction = !r->fog_ && SceneRefracts(s);
  p.scattering = r->fog_ && any_light && r->fog_model_.scatters();
  r->needs_normal_ = any_light || p.reflection || p.refraction || options.layers.normal;
  r->smooth_normals_ = s.smooth_normals && !r->fog_ && meta.has_normal;
  r->needs_attributes_ =
      meta.has_color || any_light || p.reflection || p.refraction || options.layers.normal;
  r->eps_t_ = 1e-7 * std::max(meta.voxel_size, 1e-300);
  if (options.lod != 0.0) {
    VOX_ASSIGN_OR_RETURN(LodTracer lt, LodTracer::Create(volume, options.lod_levels, options.lod));
    r->lod_ = std::move(lt);
    r->primary_cone_ = PrimaryConeOf(cam, meta.voxel_size);
  }
  // One directional light with shadows lights the fog: its light is kept on
  // a lattice in light space, whose columns each take one ray.
  const Light* sun = nullptr;
  int lights = 0;
  for (const Light& l : s.lights)
    if (l.intensity > 0) ++lights, sun = &l;
  if (r->fog_ && p.scattering && r->lod_ && s.volume.light_lattice && lights == 1 &&
      sun->type == Light::Type::kDirectional && sun->shadows) {
    LightColumns& c = r->columns_;
    const glm::dvec3 to_light = xf.world_to_grid_linear * -sun->direction;
    c.voxels_per_unit = glm::length(to_light);
    if (c.voxels_per_unit > 0 && std::isfinite(c.voxels_per_unit)) {
      c.on = true;
      c.n = to_light / c.voxels_per_unit;
      c.travel = -to_light;
      // u: across n, from the axis n is least along; v = n x u.
      const glm::dvec3 a = std::abs(c.n.x) <= std::abs(c.n.y) && std::abs(c.n.x) <= std::abs(c.n.z)
                               ? glm::dvec3(1, 0, 0)
                           : std::abs(c.n.y) <= std::abs(c.n.z) ? glm::dvec3(0, 1, 0)
                                                                : glm::dvec3(0, 0, 1);
      c.u = glm::normalize(glm::cross(c.n, a));
      c.v = glm::cross(c.n, c.u);
      const double g = std::ldexp(1.0, view.levels);
      c.top = 0.0;
      for (int k = 0; k < 8; ++k)
        c.top = std::max(c.top, glm::dot(glm::dvec3(k & 1, (k >> 1) & 1, (k >> 2) & 1) * g, c.n));
      c.light = sun->color * sun->intensity;
    }
  }
  return r;
}

std::string Renderer::SplitString() const {
  return tracer_.single_step() ? std::to_string(tracer_.n1()) + " (single step)"
                               : std::to_string(tracer_.n1()) + "+" + std::to_string(tracer_.n2());
}

BeamCorners Renderer::BlockCorners(double x0, double y0, double x1, double y1) const {
  BeamCorners b;
  const double xs[4] = {x0, x1, x1, x0}, ys[4] = {y0, y0, y1, y1};
  for (int i = 0; i < 4; ++i) {
    const WorldRay wr = camera_.PixelRay(xs[i], ys[i]);
    b.o[i] = xf_.WorldToGrid(wr.origin);
    b.d[i] = xf_.world_to_grid_linear * wr.dir;
  }
  return b;
}

void Renderer::ShadePixel(const WorldRay& wr, TraceContext& cx, Sample* out,
                          const StartPlane* start, const Cone* cone) const {
  ++cx.c->rays[kRayPrimary];
  const Ray gr{xf_.WorldToGrid(wr.origin), xf_.world_to_grid_linear * wr.dir};
  const bool lod = lod_.has_value();
  if (cone == nullptr) cone = &primary_cone_;
  if (fog_) {
    glm::dvec3 T(1.0);
    double first_t = kInf;
    glm::dvec3 l = Fog(gr, cx, &T, &first_t, lod ? cone : nullptr, start);
    // Premultiplied: the background only when the scene puts it in the EXR
    // (seen through each channel's transmittance; alpha: their mean).
    out->color = scene_.background_in_exr ? l + T * Background(wr.dir) : l;
    out->alpha = 1.0 - (T.x + T.y + T.z) / 3.0;
    out->z = first_t;
    out->hit = first_t < kInf;
    out->normal = glm::dvec3(0.0);
    out->voxel = glm::i64vec3(0);
    if (out->hit) SetHitGeometry(wr, out);
    return;
  }
  Hit h;
  VoxelAttributes a;
  int level = 0;
  if (options_.first_hits_only) {
    if (!(lod ? FindHitLod(gr, *cone, /*skip_start_run=*/false, cx, &h, &level, nullptr, start)
              : FindHit(gr, /*skip_start_run=*/false, cx, &h, nullptr, start)))
      return;
    out->hit = true;
    out->level = level;
    out->alpha = 1.0;
    out->z = h.t;
    out->depth = h.t * glm::dot(wr.dir, camera_.forward());
    out->position = glm::dvec3(0.0);
    out->normal = glm::dvec3(0.0);
    out->voxel = (h.voxel << int64_t(level)) + volume_->meta().origin;
    return;
  }
  if (!(lod ? FindHitLod(gr, *cone, /*skip_start_run=*/false, cx, &h, &level, SurfaceAttrs(&a),
                        start)
            : FindHit(gr, /*skip_start_run=*/false, cx, &h, SurfaceAttrs(&a), start))) {
    if (!cx.failed() && scene_.background_in_exr) out->color = Background(wr.dir);
    return;
  }
  out->hit = true;
  out->level = level;
  out->alpha = 1.0;
  out->z = h.t;
  SetHitGeometry(wr, out);
  // A coarse cell's voxel layer names its first base voxel.
  out->voxel = (h.voxel << int64_t(level)) + volume_->meta().origin;
  const LodRay lr{*cone, level};
  out->color = ShadeSurface(gr, wr.dir, h, a, 0, cx, &out->normal, lod ? &lr : nullptr);
}

void Renderer::SetHitGeometry(const WorldRay& wr, Sample* s) const {
  // The ray parameter is the world distance along the unit direction.
  s->depth = s->z * glm::dot(wr.dir, camera_.forward());
  s->position = wr.origin + s->z * wr.dir;
}

int Renderer::PrimaryStopLevel(const WorldRay& wr, const Cone& cone, TraceContext& cx,
                               double* t) const {
  const Ray gr{xf_.WorldToGrid(wr.origin), xf_.world_to_grid_linear * wr.dir};
  Hit h;
  int level = 0;
  if (!FindHitLod(gr, cone, /*skip_start_run=*/false, cx, &h, &level, nullptr)) return -1;
  if (t != nullptr) *t = h.t;
  return level;
}

void Renderer::FirstBricks(const TileRect& rect, int stride, std::vector<uint32_t>* ids) const {
  OctreeView view = volume_->view();
  if (view.bricks == nullptr || stride < 1) return;
  const size_t first = ids->size();
  // One brick per ray: the second is needed only when the ray passes the
  // first without a hit, and recording two per ray read 25% more bytes
  // than the frame needed (the 8192^3 sphere).
  RecordingSource recorder(ids, 1);
  view.bricks = &recorder;
  auto tracer = RenderTracer::Create(view, tracer_.n1());
  if (!tracer.ok()) return;
  for (int py = stride / 2; py < rect.h; py += stride)
    for (int px = stride / 2; px < rect.w; px += stride) {
      const WorldRay wr = camera_.PixelRay(rect.x0 + px + 0.5, rect.y0 + py + 0.5);
      const Ray gr{xf_.WorldToGrid(wr.origin), xf_.world_to_grid_linear * wr.dir};
      recorder.Restart();
      (void)tracer->FirstHit(gr);
    }
  std::sort(ids->begin() + ptrdiff_t(first), ids->end());
  ids->erase(std::unique(ids->begin() + ptrdiff_t(first), ids->end()), ids->end());
}

}  // namespace vox

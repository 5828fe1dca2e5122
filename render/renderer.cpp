// The Renderer's set-up (passes, default lights, per-thread state) and its
// pixel and tile loop; surfaces are in surface.cpp, fog in fog.cpp.
#include "render/renderer.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

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

struct Renderer::ThreadState {
  std::unique_ptr<LendingBrickTable> bricks;
  RenderTracer tracer;
  std::unique_ptr<LodThread> lod;  // --lod: the coarse levels' tracers and table
};

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

struct Renderer::Sample {
  glm::dvec3 color{0.0};
  double alpha = 0.0;
  double z = kInf;
  bool hit = false;
  // Set with hit = true only (left unset otherwise: zeroing the whole
  // sample per ray cost 3% of a frame).
  glm::dvec3 normal;
  glm::i64vec3 voxel;
};

StatusOr<std::unique_ptr<Renderer>> Renderer::Create(Volume* volume, const Camera& camera,
                                                     const Scene& scene,
                                                     const RenderOptions& options) {
  const StoreMeta& meta = volume->meta();
  OctreeView view = volume->view();
  int n1 = options.n1 > 0 ? options.n1 : DefaultFirstStepLevels(view.levels);
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
  p.scattering = r->fog_ && any_light && s.volume.scattering > 0;
  r->needs_normal_ = any_light || p.reflection || p.refraction || options.layers.normal;
  r->needs_attributes_ =
      meta.has_color || any_light || p.reflection || p.refraction || options.layers.normal;
  r->eps_t_ = 1e-7 * std::max(meta.voxel_size, 1e-300);
  if (options.lod != 0.0) {
    VOX_ASSIGN_OR_RETURN(LodTracer lt, LodTracer::Create(volume, options.lod_levels, options.lod));
    r->lod_ = std::move(lt);
    r->primary_cone_ = PrimaryConeOf(cam, meta.voxel_size);
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

void Renderer::ShadePixel(const WorldRay& wr, Ctx& cx, Sample* out,
                          const StartPlane* start) const {
  ++cx.c->rays[kRayPrimary];
  const Ray gr{xf_.WorldToGrid(wr.origin), xf_.world_to_grid_linear * wr.dir};
  const bool lod = lod_.has_value();
  if (fog_) {
    double T = 1.0, first_t = kInf;
    glm::dvec3 l = Fog(gr, cx, &T, &first_t, lod ? &primary_cone_ : nullptr);
    out->color = l + T * Background(wr.dir);
    out->alpha = 1.0 - T;
    out->z = first_t;
    out->hit = first_t < kInf;
    out->normal = glm::dvec3(0.0);
    out->voxel = glm::i64vec3(0);
    return;
  }
  Hit h;
  VoxelAttributes a;
  int level = 0;
  if (!(lod ? FindHitLod(gr, primary_cone_, /*skip_start_run=*/false, cx, &h, &level,
                         SurfaceAttrs(&a))
            : FindHit(gr, /*skip_start_run=*/false, cx, &h, SurfaceAttrs(&a), start))) {
    if (!cx.failed()) out->color = Background(wr.dir);
    return;
  }
  out->hit = true;
  out->alpha = 1.0;
  out->z = h.t;
  // A coarse cell's voxel layer names its first base voxel.
  out->voxel = (h.voxel << int64_t(level)) + volume_->meta().origin;
  const LodRay lr{primary_cone_, level};
  out->color = ShadeSurface(gr, wr.dir, h, a, 0, cx, &out->normal, lod ? &lr : nullptr);
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

Status Renderer::RenderTile(const TileRect& rect, TileBuffer* buf, RenderCounters* counters,
                            ThreadState* ts) const {
  Ctx cx{ts ? &ts->tracer : &tracer_, counters, OkStatus()};
  if (ts != nullptr) cx.lod = ts->lod.get();
  const int spp = scene_.samples_per_pixel;
  const ImageLayers& layers = options_.layers;
  const float inf = std::numeric_limits<float>::infinity();
  // Shades pixel (px, py) of the tile. Ok, an error, or (no-wait mode only)
  // Unavailable: a brick it needs is not in memory; the pixel is untouched
  // and its partial work is not counted.
  // Beam start distances: one StartPlane per block of the tile.
  const int bs = std::max(1, options_.beam_block);
  const int nbx = (rect.w + bs - 1) / bs, nby = (rect.h + bs - 1) / bs;
  const bool beam = options_.beam && !fog_ && !lod_;
  std::vector<StartPlane> planes;
  const bool use_planes = beam;
  if (use_planes) {
    planes.resize(size_t(nbx) * size_t(nby));
    const OctreeView view = volume_->view();
    for (int by = 0; by < nby; ++by)
      for (int bx = 0; bx < nbx; ++bx) {
        const int x0 = rect.x0 + bx * bs, y0 = rect.y0 + by * bs;
        const int x1 = std::min(x0 + bs, rect.x0 + rect.w);
        const int y1 = std::min(y0 + bs, rect.y0 + rect.h);
        planes[by * nbx + bx] = BeamStartPlane(view, tracer_.n1(), BlockCorners(x0, y0, x1, y1));
      }
  }
  // Each sample's screen coordinates, per column and per row of the tile
  // (Camera::ScreenX/ScreenY: the rays are PixelRay's, bit for bit).
  std::vector<double> screen_x(size_t(spp) * size_t(rect.w)), screen_y(size_t(spp) * size_t(rect.h));
  for (int k = 0; k < spp; ++k) {
    double ox = 0.5, oy = 0.5;
    if (spp > 1) {
      ox = (k + 0.5) / spp;
      oy = RadicalInverse2(uint32_t(k) + 1u);
    }
    for (int px = 0; px < rect.w; ++px)
      screen_x[size_t(k) * rect.w + px] = camera_.ScreenX(rect.x0 + px + ox);
    for (int py = 0; py < rect.h; ++py)
      screen_y[size_t(k) * rect.h + py] = camera_.ScreenY(rect.y0 + py + oy);
  }
  // The primary rays of one row of the tile (all samples), and the row's
  // beam blocks, made when the row's first pixel is shaded.
  std::vector<WorldRay> row_rays(size_t(spp) * size_t(rect.w));
  std::vector<int> block_x(size_t(rect.w));
  for (int px = 0; px < rect.w; ++px) block_x[px] = px / bs;
  int row_y = -1;
  const StartPlane* row_planes = nullptr;
  auto row = [&](int py) -> const WorldRay* {
    if (py != row_y) {
      for (int k = 0; k < spp; ++k)
        camera_.ScreenRays(&screen_x[size_t(k) * rect.w], screen_y[size_t(k) * rect.h + py], rect.w,
                           &row_rays[size_t(k) * rect.w]);
      if (use_planes) row_planes = &planes[size_t(py / bs) * nbx];
      row_y = py;
    }
    return row_rays.data();
  };
  const double inv_spp = 1.0 / spp;
  auto store = [&](int px, int py, const glm::dvec3& color, double alpha, double z,
                   const glm::dvec3& normal, bool any_hit, const glm::i64vec3& voxel) {
    ++counters->pixels;
    if (any_hit) ++counters->hit_pixels;
    *buf->at(kChR, px, py) = float(color.r * inv_spp);
    *buf->at(kChG, px, py) = float(color.g * inv_spp);
    *buf->at(kChB, px, py) = float(color.b * inv_spp);
    *buf->at(kChA, px, py) = float(alpha * inv_spp);
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
  };
  auto shade = [&](int px, int py) -> Status {
    const WorldRay* rays = row(py);
    const StartPlane* start = use_planes ? &row_planes[block_x[px]] : nullptr;
    if (start != nullptr && start->s_min == kInf) {
      // The block's beam meets nothing (its corner rays are finite and near:
      // BeamStartPlane), so each sample is a miss, as its walk would find:
      // no walk, no per-sample set-up (ShadePixel is not called).
      glm::dvec3 color(0.0);
      for (int k = 0; k < spp; ++k) color += Background(rays[size_t(k) * rect.w + px].dir);
      counters->rays[kRayPrimary] += uint64_t(spp);
      counters->trace.rays += uint64_t(spp);
      store(px, py, color, 0.0, kInf, glm::dvec3(0.0), false, glm::i64vec3(0));
      return OkStatus();
    }
    glm::dvec3 color(0.0), normal(0.0);
    double alpha = 0.0, z = kInf;
    glm::i64vec3 voxel(0);
    bool any_hit = false;
    for (int k = 0; k < spp; ++k) {
      Sample s;
      ShadePixel(rays[size_t(k) * rect.w + px], cx, &s, start);
      if (cx.failed()) {
        Status e = std::move(cx.error);
        cx.error = OkStatus();
        return e;
      }
      color += s.color;
      alpha += s.alpha;
      if (s.hit && s.z < z) {
        z = s.z;
        normal = s.normal;
        voxel = s.voxel;
      }
      any_hit = any_hit || s.hit;
    }
    store(px, py, color, alpha, z, normal, any_hit, voxel);
    return OkStatus();
  };

  LendingBrickTable* table = ts != nullptr ? ts->bricks.get() : nullptr;
  if (!options_.read_ahead || table == nullptr) {
    for (int py = 0; py < rect.h; ++py)
      for (int px = 0; px < rect.w; ++px) VOX_RETURN_IF_ERROR(shade(px, py));
    return OkStatus();
  }

  // Deferred misses (RenderOptions::read_ahead): no-wait passes while they
  // finish a good share of what is left, then one pass that waits.
  struct NoWait {  // the table waits again however this returns
    LendingBrickTable* t;
    ~NoWait() {
      t->set_no_wait(false);
      t->wanted().clear();
    }
  } no_wait{table};
  auto flush = [&] {
    std::vector<uint32_t>& w = table->wanted();
    if (w.empty()) return;
    options_.read_ahead(w);
    w.clear();
  };
  std::vector<uint32_t> pending, next;  // pixels as py * w + px
  pending.reserve(size_t(rect.w) * size_t(rect.h));
  for (int py = 0; py < rect.h; ++py)
    for (int px = 0; px < rect.w; ++px) pending.push_back(uint32_t(py * rect.w + px));
  constexpr int kMaxNoWaitPasses = 4;
  constexpr size_t kFlushEvery = 64;  // pixels: a tile row's misses go out together, in runs
  for (int pass = 0; !pending.empty(); ++pass) {
    const bool last = pass == kMaxNoWaitPasses;
    table->set_no_wait(!last);
    next.clear();
    size_t since_flush = 0;
    for (uint32_t p : pending) {
      const int px = int(p % uint32_t(rect.w)), py = int(p / uint32_t(rect.w));
      const RenderCounters before = *counters;
      Status s = shade(px, py);
      if (!s.ok()) {
        if (last || s.code() != StatusCode::kUnavailable) return s;
        *counters = before;
        ++counters->deferred_pixels;
        next.push_back(p);
      }
      if (++since_flush == kFlushEvery) {
        flush();
        since_flush = 0;
      }
    }
    flush();
    // Few finished: the reads are behind; wait for them in the last pass.
    if (!last && next.size() * 4 > pending.size() * 3 && pass > 0) pass = kMaxNoWaitPasses - 1;
    pending.swap(next);
  }
  return OkStatus();
}

}  // namespace vox

// The Renderer's tile loop: the tile's primary rays a row at a time, beam
// blocks answered without a walk, deferred passes for pixels whose bricks
// are still being read, and the antialiasing of coarse silhouettes
// (RenderOptions::silhouette_grid).
#include <algorithm>
#include <limits>

#include "render/internal/tracing.h"
#include "render/renderer.h"
#include "storage/brick_table.h"

namespace vox {
namespace {

using render_internal::kInf;

double RadicalInverse2(uint32_t k) {
  k = (k << 16) | (k >> 16);
  k = ((k & 0x55555555u) << 1) | ((k & 0xAAAAAAAAu) >> 1);
  k = ((k & 0x33333333u) << 2) | ((k & 0xCCCCCCCCu) >> 2);
  k = ((k & 0x0F0F0F0Fu) << 4) | ((k & 0xF0F0F0F0u) >> 4);
  k = ((k & 0x00FF00FFu) << 8) | ((k & 0xFF00FF00u) >> 8);
  return double(k) * (1.0 / 4294967296.0);
}

// Sample k's position in its pixel, of `spp` samples: the centre for one,
// else a (0,2)-sequence (k + 1/2) / spp, radical inverse of k + 1.
void SampleOffset(int k, int spp, double* ox, double* oy) {
  *ox = 0.5;
  *oy = 0.5;
  if (spp > 1) {
    *ox = (k + 0.5) / spp;
    *oy = RadicalInverse2(uint32_t(k) + 1u);
  }
}

// A pixel's level for the silhouette test: -1 a miss.
constexpr int8_t kMissLevel = -1;
// Not traced yet (a neighbour across the tile's border), or outside the image.
constexpr int8_t kUnknownLevel = -2, kNoPixel = -3;

}  // namespace

// A pixel's samples, summed; written divided by their count.
struct Renderer::PixelValue {
  glm::dvec3 color{0.0}, normal{0.0}, position{0.0};
  double alpha = 0.0, z = kInf, depth = kInf;  // z: along the ray; depth: planar
  glm::i64vec3 voxel{0};
  bool any_hit = false;
  int level = kMissLevel;  // the largest LOD level of the samples' stops
  double weight = 1.0;     // 1 / samples

  void Add(const Sample& s) {
    color += s.color;
    alpha += s.alpha;
    if (s.hit && s.z < z) {
      z = s.z;
      depth = s.depth;
      position = s.position;
      normal = s.normal;
      voxel = s.voxel;
    }
    if (s.hit) {
      any_hit = true;
      level = std::max(level, s.level);
    }
  }
};

// The primary rays of a tile, a row at a time (all samples of the row's
// pixels, made when the row's first pixel is shaded: Camera::ScreenRays,
// bit for bit Camera::PixelRay), and each pixel's beam StartPlane.
class Renderer::TileRays {
 public:
  TileRays(const Renderer& r, const TileRect& rect)
      : camera_(r.camera_), rect_(rect), spp_(r.scene_.samples_per_pixel),
        block_(std::max(1, r.options_.beam_block)) {
    if (r.options_.beam) planes_ = r.BeamPlanes(rect);
    screen_x_.resize(size_t(spp_) * size_t(rect.w));
    screen_y_.resize(size_t(spp_) * size_t(rect.h));
    for (int k = 0; k < spp_; ++k) {
      double ox, oy;
      SampleOffset(k, spp_, &ox, &oy);
      for (int px = 0; px < rect.w; ++px)
        screen_x_[size_t(k) * rect.w + px] = camera_.ScreenX(rect.x0 + px + ox);
      for (int py = 0; py < rect.h; ++py)
        screen_y_[size_t(k) * rect.h + py] = camera_.ScreenY(rect.y0 + py + oy);
    }
    row_rays_.resize(size_t(spp_) * size_t(rect.w));
    block_x_.resize(size_t(rect.w));
    for (int px = 0; px < rect.w; ++px) block_x_[px] = px / block_;
  }

  int spp() const { return spp_; }
  // Sample k of pixel px in row py.
  const WorldRay& At(int px, int py, int k) {
    MakeRow(py);
    return row_rays_[size_t(k) * rect_.w + px];
  }
  // The beam StartPlane of pixel (px, py); nullptr without beams.
  const StartPlane* Start(int px, int py) const {
    if (planes_.empty()) return nullptr;
    const int blocks_x = (rect_.w + block_ - 1) / block_;
    return &planes_[size_t(py / block_) * blocks_x + block_x_[px]];
  }

 private:
  void MakeRow(int py) {
    if (py == row_y_) return;
    for (int k = 0; k < spp_; ++k)
      camera_.ScreenRays(&screen_x_[size_t(k) * rect_.w], screen_y_[size_t(k) * rect_.h + py],
                         rect_.w, &row_rays_[size_t(k) * rect_.w]);
    row_y_ = py;
  }

  const Camera& camera_;
  TileRect rect_;
  int spp_, block_;
  std::vector<StartPlane> planes_;
  std::vector<double> screen_x_, screen_y_;  // per sample: per column, per row
  std::vector<WorldRay> row_rays_;
  std::vector<int> block_x_;
  int row_y_ = -1;
};

std::vector<StartPlane> Renderer::BeamPlanes(const TileRect& rect) const {
  const int bs = std::max(1, options_.beam_block);
  const int blocks_x = (rect.w + bs - 1) / bs, blocks_y = (rect.h + bs - 1) / bs;
  std::vector<StartPlane> planes(size_t(blocks_x) * size_t(blocks_y));
  const OctreeView view = volume_->view();
  for (int by = 0; by < blocks_y; ++by)
    for (int bx = 0; bx < blocks_x; ++bx) {
      const int x0 = rect.x0 + bx * bs, y0 = rect.y0 + by * bs;
      const int x1 = std::min(x0 + bs, rect.x0 + rect.w);
      const int y1 = std::min(y0 + bs, rect.y0 + rect.h);
      planes[size_t(by) * blocks_x + bx] =
          BeamStartPlane(view, tracer_.n1(), BlockCorners(x0, y0, x1, y1));
    }
  return planes;
}

void Renderer::WritePixel(const PixelValue& v, int px, int py, TileBuffer* buf) const {
  const float inf = std::numeric_limits<float>::infinity();
  *buf->at(kChR, px, py) = float(v.color.r * v.weight);
  *buf->at(kChG, px, py) = float(v.color.g * v.weight);
  *buf->at(kChB, px, py) = float(v.color.b * v.weight);
  *buf->at(kChA, px, py) = float(v.alpha * v.weight);
  const bool hit = v.z < kInf;
  *buf->at(kChZ, px, py) = hit ? float(v.depth) : inf;
  if (options_.layers.normal) {
    *buf->at(kChNx, px, py) = float(v.normal.x);
    *buf->at(kChNy, px, py) = float(v.normal.y);
    *buf->at(kChNz, px, py) = float(v.normal.z);
  }
  if (options_.layers.voxel) {
    // NaN where no voxel was hit (misses; fog names no single voxel), so a
    // miss cannot be read as voxel (0, 0, 0).
    // With level of detail, a coarse stop whose exact pick found no voxel
    // (PickExactly) has z = inf: no voxel either.
    const bool voxel = hit && !fog_;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    *buf->at(kChVi, px, py) = voxel ? float(v.voxel.x) : nan;
    *buf->at(kChVj, px, py) = voxel ? float(v.voxel.y) : nan;
    *buf->at(kChVk, px, py) = voxel ? float(v.voxel.z) : nan;
  }
  if (options_.layers.position) {
    *buf->at(kChPx, px, py) = hit ? float(v.position.x) : 0.0f;
    *buf->at(kChPy, px, py) = hit ? float(v.position.y) : 0.0f;
    *buf->at(kChPz, px, py) = hit ? float(v.position.z) : 0.0f;
  }
  if (options_.layers.distance) *buf->at(kChDist, px, py) = hit ? float(v.z) : inf;
}

Status Renderer::ShadeTilePixel(int px, int py, TileRays& rays, TraceContext& cx,
                                PixelValue* value) const {
  const int spp = rays.spp();
  value->weight = 1.0 / spp;
  const StartPlane* start = rays.Start(px, py);
  // (With level of detail a coarse cell may be occupied where the base has
  // nothing: such a block's rays still walk the coarse levels.)
  if (start != nullptr && start->s_min == kInf && !lod_) {
    // The block's beam meets nothing (its corner rays are finite and near:
    // BeamStartPlane), so each sample is a miss, as its walk would find:
    // no walk, no per-sample set-up (ShadePixel is not called).
    if (scene_.background_in_exr)
      for (int k = 0; k < spp; ++k) value->color += Background(rays.At(px, py, k).dir);
    cx.c->rays[kRayPrimary] += uint64_t(spp);
    cx.c->trace.rays += uint64_t(spp);
    return OkStatus();
  }
  for (int k = 0; k < spp; ++k) {
    Sample s;
    ShadePixel(rays.At(px, py, k), cx, &s, start);
    if (lod_ && !cx.failed()) PickExactly(rays.At(px, py, k), cx, &s, start);
    if (cx.failed()) {
      Status e = std::move(cx.error);
      cx.error = OkStatus();
      return e;
    }
    value->Add(s);
  }
  return OkStatus();
}

Status Renderer::RenderTile(const TileRect& rect, TileBuffer* buf, RenderCounters* counters,
                            ThreadState* ts) const {
  TraceContext cx{ts ? &ts->tracer : &tracer_, counters, OkStatus()};
  render_internal::FogLightCache tile_light;  // fog without a thread's state: the tile's
  cx.light_cache = &tile_light;
  if (ts != nullptr) {
    cx.lod = ts->lod.get();
    cx.light_cache = &ts->light_cache;
    cx.bricks = ts->bricks.get();
  }
  TileRays rays(*this, rect);
  // Each pixel's stop level, for the silhouette test (antialias() only).
  std::vector<int8_t> levels;
  if (antialias()) levels.assign(size_t(rect.w) * size_t(rect.h), kMissLevel);
  LendingBrickTable* table = ts != nullptr ? ts->bricks.get() : nullptr;
  if (!options_.read_ahead || table == nullptr) {
    VOX_RETURN_IF_ERROR(ShadeTileWaiting(rect, rays, cx, buf, &levels));
  } else {
    VOX_RETURN_IF_ERROR(ShadeTileDeferred(rect, rays, cx, table, buf, &levels));
  }
  if (antialias()) VOX_RETURN_IF_ERROR(RefineSilhouettes(rect, levels, cx, buf));
  return OkStatus();
}

Status Renderer::ShadeTileWaiting(const TileRect& rect, TileRays& rays, TraceContext& cx,
                                  TileBuffer* buf, std::vector<int8_t>* levels) const {
  // Pixels in blocks of kPixelBlock^2, row by row in each: neighbouring
  // rays read the same bricks' cells and densities, and a block's fit the
  // processor's cache where a tile's rows do not.
  constexpr int kPixelBlock = 16;
  for (int by = 0; by < rect.h; by += kPixelBlock)
    for (int bx = 0; bx < rect.w; bx += kPixelBlock)
      for (int py = by; py < std::min(rect.h, by + kPixelBlock); ++py)
        for (int px = bx; px < std::min(rect.w, bx + kPixelBlock); ++px) {
          PixelValue v;
          VOX_RETURN_IF_ERROR(ShadeTilePixel(px, py, rays, cx, &v));
          ++cx.c->pixels;
          if (v.any_hit) ++cx.c->hit_pixels;
          WritePixel(v, px, py, buf);
          if (!levels->empty()) (*levels)[size_t(py) * rect.w + px] = int8_t(v.level);
        }
  return OkStatus();
}

Status Renderer::ShadeTileDeferred(const TileRect& rect, TileRays& rays, TraceContext& cx,
                                   LendingBrickTable* table, TileBuffer* buf,
                                   std::vector<int8_t>* levels) const {
  // No-wait passes while they finish a good share of what is left, then one
  // pass that waits.
  struct NoWait {  // the table waits again however this returns
    LendingBrickTable* t;
    ~NoWait() {
      t->set_no_wait(false);
      t->wanted().clear();
    }
  } no_wait{table};
  auto flush = [&] {
    std::vector<uint32_t>& wanted = table->wanted();
    if (wanted.empty()) return;
    options_.read_ahead(wanted);
    wanted.clear();
  };
  RenderCounters* counters = cx.c;
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
      PixelValue v;
      Status s = ShadeTilePixel(px, py, rays, cx, &v);
      if (s.ok()) {
        ++counters->pixels;
        if (v.any_hit) ++counters->hit_pixels;
        WritePixel(v, px, py, buf);
        if (!levels->empty()) (*levels)[p] = int8_t(v.level);
      } else {
        // Unavailable: a brick the pixel needs is not in memory; the pixel
        // is untouched and its partial work is not counted.
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

Status Renderer::RefineSilhouettes(const TileRect& rect, const std::vector<int8_t>& levels,
                                   TraceContext& cx, TileBuffer* buf) const {
  const int spp = scene_.samples_per_pixel;
  // Levels of the tile's pixels and of the ring around it, (px + 1, py + 1);
  // the ring's are traced when first asked, as the pixels' own samples
  // would find them, so a pixel's test does not depend on the tiling.
  const int ring_w = rect.w + 2;
  std::vector<int8_t> at(size_t(ring_w) * size_t(rect.h + 2), kUnknownLevel);
  for (int py = 0; py < rect.h; ++py)
    std::copy_n(&levels[size_t(py) * rect.w], rect.w, &at[size_t(py + 1) * ring_w + 1]);
  auto level_at = [&](int px, int py) -> int {
    int8_t& l = at[size_t(py + 1) * ring_w + size_t(px + 1)];
    if (l != kUnknownLevel) return l;
    const int x = rect.x0 + px, y = rect.y0 + py;
    if (x < 0 || y < 0 || x >= camera_.width || y >= camera_.height) return l = kNoPixel;
    int level = kMissLevel;
    for (int k = 0; k < spp && !cx.failed(); ++k) {
      double ox, oy;
      SampleOffset(k, spp, &ox, &oy);
      level = std::max(level, PrimaryStopLevel(camera_.PixelRay(x + ox, y + oy), primary_cone_, cx));
      ++cx.c->lod.border_rays;
    }
    return l = int8_t(level);
  };
  // A silhouette pixel: a coarse stop next to a miss (8-neighbourhood). A
  // coarse cell is conservative (occupied when any of its voxels is), so
  // such a pixel is covered by less than its centre ray says. (Refining the
  // misses next to a coarse stop too doubled the work for no measurable
  // gain: docs/lod.md.)
  auto silhouette = [&](int px, int py) {
    if (levels[size_t(py) * rect.w + px] <= 0) return false;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if ((dx != 0 || dy != 0) && level_at(px + dx, py + dy) == kMissLevel) return true;
    return false;
  };
  const int grid = options_.silhouette_grid;
  const Cone cone{primary_cone_.w0 / grid, primary_cone_.spread / grid};
  for (int py = 0; py < rect.h; ++py)
    for (int px = 0; px < rect.w; ++px) {
      if (!silhouette(px, py)) {
        if (cx.failed()) return cx.error;
        continue;
      }
      PixelValue v;
      v.weight = 1.0 / (grid * grid);
      for (int j = 0; j < grid; ++j)
        for (int i = 0; i < grid; ++i) {
          Sample s;
          const WorldRay wr = camera_.PixelRay(rect.x0 + px + (i + 0.5) / grid, rect.y0 + py + (j + 0.5) / grid);
          ShadePixel(wr, cx, &s, nullptr, &cone);
          if (!cx.failed()) PickExactly(wr, cx, &s, nullptr);
          if (cx.failed()) return cx.error;
          v.Add(s);
        }
      ++cx.c->lod.refined_pixels;
      cx.c->lod.refine_rays += uint64_t(grid * grid);
      if (!v.any_hit) --cx.c->hit_pixels;  // the pixel's own stop was a hit
      WritePixel(v, px, py, buf);
    }
  return OkStatus();
}

}  // namespace vox

// vox::Renderer: shades the pixels of one tile by discrete ray tracing of a
// Volume (storage/store.h; core/tracer.h traces it), simulating only the
// effects the scene calls for. The passes are decided once, at Create:
//   - shadows:     a light with "shadows": true (and intensity > 0), surfaces only;
//   - reflection:  a material with reflect > 0 and max_depth > 0;
//   - refraction:  a material with transmit > 0 and max_depth > 0;
//   - volume:      fog volumes only (level sets are never integrated);
//   - scattering:  fog with scattering > 0 and a light.
// Surfaces are shaded from the stored normals (index-space gradients taken to
// world space by the inverse transpose of index_to_world), interpolated
// between the voxels around the hit point unless the scene asks for flat
// normals; a voxel without a normal uses the face its ray entered through. A
// normal facing away from the ray (a voxel seen past its silhouette) is
// mirrored across the plane perpendicular to the ray: it keeps its side
// towards the lights instead of turning into the surface.
//
// Every secondary ray (shadow, reflection, refraction, transmittance) is made
// by SpawnRay. Rays leaving a surface (shadow, reflection, a refracted ray's
// exit) start 2.5 voxels out along the normal (clear of the surface's own
// staircase at grazing angles) and skip any run of occupied voxels contiguous
// with their start, so a surface never shadows or reflects itself, while
// anything after an empty voxel occludes. Refracted rays enter at the face
// itself and cross the object to the end of the first occupied run whose
// stored normal faces along the ray (the back surface; a level set's interior
// is hollow).
//
// Fog: absorption on the exact DDA segments (each occupied voxel's entry and
// exit t), extinction = (absorption + scattering) * density per world unit;
// single scattering with isotropic phase, the light attenuated by a
// transmittance ray to the light from sample points along the ray (every
// volume.light_step voxels, closer where the fog is thick: render/scene.h),
// interpolated linearly between them. With a level-of-detail pyramid, a
// transmittance ray's cells widen along it (volume.shadow_lod). No random
// numbers: a pixel's value depends on the pixel alone. A = 1 - transmittance.
// Integration stops once transmittance falls below 1e-6.
//
// Level of detail (RenderOptions::lod, docs/lod.md): primary rays carry a
// cone one pixel wide and stop at the first occupied cell of the volume's
// pyramid no larger than F times the cone (render/lod.h); a coarse hit's
// shadow and reflection rays carry the cone on, a level-0 hit's are exact,
// fog integrates the cells' mean density. Rays whose level stays 0 take
// exactly the path without LOD.
//
// The code: renderer.cpp (set-up, the pixel and tile loop), surface.cpp
// (hits, surface shading, reflection, refraction), fog.cpp (fog and
// transmittance), lod_render.cpp (level-of-detail rays);
// render/internal/tracing.h holds what they share.
//
// Thread safety: a Renderer is immutable after Create; RenderTile is const
// and runs concurrently (one TileBuffer and RenderCounters per thread).
#ifndef VOX_RENDER_RENDERER_H_
#define VOX_RENDER_RENDERER_H_

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <optional>
#include <string>
#include <vector>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "core/ray.h"
#include "core/util/status.h"
#include "core/tracer.h"
#include "render/beam.h"
#include "render/camera.h"
#include "render/exr.h"
#include "render/grid_transform.h"
#include "render/lod.h"
#include "render/scene.h"
#include "render/tiles.h"
#include "storage/store.h"

namespace vox {

namespace render_internal {
class FogLightCache;
}  // namespace render_internal

enum RayKind { kRayPrimary, kRayShadow, kRayReflection, kRayRefraction, kRayVolume, kNumRayKinds };
const char* RayKindName(int kind);

struct RenderCounters {
  TraceCounters trace;  // all rays' DDA work
  uint64_t rays[kNumRayKinds] = {};
  uint64_t pixels = 0;
  uint64_t hit_pixels = 0;  // pixels with at least one primary hit (or fog)
  uint64_t attribute_lookups = 0;
  // Pixels put aside because a brick was still being read (RenderOptions::
  // read_ahead), once per time; their rays' other counters count only the
  // shading that completed.
  uint64_t deferred_pixels = 0;
  LodCounters lod;  // --lod: stops by level
  void Add(const RenderCounters& o);
};

struct RenderPasses {
  bool shading = true;  // surfaces: local lighting from normals
  bool shadows = false;
  bool reflection = false;
  bool refraction = false;
  bool volume = false;
  bool scattering = false;
  std::string ToString() const;
};

struct RenderOptions {
  int n1 = 0;  // first-step levels of the two-step traversal; 0: DefaultFirstStepLevels
  ImageLayers layers;
  // Size of each thread's pinned-brick table, log2 of its slots (0..16); -1:
  // from the volume's cache capacity (LendingBrickTable::SlotBits). A memory
  // budget sets it so the pins stay within their share (SlotBitsForBytes).
  int table_slot_bits = -1;
  // Deferred misses: when set, a pixel whose rays enter a brick that is not
  // in memory is put aside instead of waiting for the read; the bricks are
  // handed to `read_ahead` (e.g. Store::Prefetch, which reads them in the
  // background), the tile's other pixels go on, and put-aside pixels are
  // shaded again in later passes, the last of which waits for reads. So a
  // cold tile keeps many reads in flight instead of one per thread. Pixels
  // come out bit-identical either way (shading is a pure function of the
  // pixel). Needs a ThreadState per thread (RenderTile's `ts`).
  std::function<void(std::span<const uint32_t>)> read_ahead;
  // Level of detail (render/lod.h, docs/lod.md): factor F > 0 turns it on;
  // lod_levels[l - 1] is level l of the volume's pyramid (not owned).
  double lod = 0.0;
  std::vector<Volume*> lod_levels;
  // Misses first: rays that pass outside the volume's occupied bbox (widened
  // by a voxel) are misses without a walk (Tracer::SetOccupiedBox); the hits
  // are the same either way.
  bool clip_to_occupied = true;
  // Beam start distances (render/beam.h): per block of beam_block^2 pixels
  // of a tile, one query of the resident top gives a plane before which the
  // block's primary rays meet nothing, and they start their walks there
  // (misses without a walk when the block meets nothing). The hits are the
  // same either way, bit for bit. Off for fog. With LOD, primary rays start
  // their level-0 segment's walk there (LodTracer::Traverse), and a block
  // that meets nothing in the base still walks the coarse levels.
  bool beam = true;
  int beam_block = 8;
  // With LOD: pixels at a coarse silhouette (a coarse stop next to a miss)
  // are shaded again from silhouette_grid^2 sub-pixel rays with cones as
  // many times narrower (render/lod.h), so their alpha is the fraction
  // covered instead of a whole dilated cell; 0: off. Surfaces only: fog
  // already integrates the cells' optical depth.
  int silhouette_grid = kDefaultSilhouetteGrid;
  // The bare loop, for comparisons with peers' first-hit loops: on level
  // sets, each primary ray's first hit only (alpha 1 on a hit, Z its depth,
  // the voxel layer its voxel), no shading, no attributes, no secondary
  // rays. Fog volumes are integrated as without it.
  bool first_hits_only = false;
};

// The tracer the renderer uses: fixed point for the DDA (64-bit words up to
// 2^26 grids, 128-bit above: see AutoTracer), double for the per-ray set-up
// and transitions (camera rays are doubles already; long double set-up costs
// x87 arithmetic on every ray and transition).
using RenderTracer = AutoTracer<double>;

class Renderer {
 public:
  // `volume` must outlive the renderer; `camera` must be Finalize()d
  // (ParseCamera, LoadCamera and DefaultCamera return finalised cameras).
  static StatusOr<std::unique_ptr<Renderer>> Create(Volume* volume, const Camera& camera,
                                                    const Scene& scene,
                                                    const RenderOptions& options);

  // Per-thread state (a small pinned-brick table in front of the volume's
  // cache: storage/brick_table.h); optional, for speed. Use one per thread;
  // release it before the volume, after the frame (it pins up to
  // 2^table_slot_bits bricks).
  struct ThreadState;
  struct ThreadStateDeleter {
    void operator()(ThreadState* ts) const;
  };
  std::unique_ptr<ThreadState, ThreadStateDeleter> NewThreadState() const;

  // Renders `rect` into `buf` (pixel (x, y) of the image at buf(x - x0, y - y0)).
  // Counts put-aside pixels' retries in counters->deferred_pixels. A pixel's
  // value depends on the pixel alone (and, with silhouette antialiasing, on
  // its neighbours' primary rays, traced again across the tile's border), never
  // on the tiling.
  Status RenderTile(const TileRect& rect, TileBuffer* buf, RenderCounters* counters,
                    ThreadState* ts = nullptr) const;

  // The bricks the primary rays of every `stride`-th pixel (in x and y) of
  // `rect` enter first, appended to `ids` (repeats removed): traced through
  // the resident top only, reading no brick, for prefetching a tile's
  // bricks before it renders.
  void FirstBricks(const TileRect& rect, int stride, std::vector<uint32_t>* ids) const;

  Volume* volume() const { return volume_; }
  const RenderPasses& passes() const { return passes_; }
  const Scene& scene() const { return scene_; }  // with the default lights filled in
  const Camera& camera() const { return camera_; }
  const ImageLayers& layers() const { return options_.layers; }
  int n1() const { return tracer_.n1(); }
  // --lod: the pyramid's tracer (nullptr when LOD is off), and the cone of
  // the primary ray through the image centre at ray parameter t.
  const LodTracer* lod() const { return lod_ ? &*lod_ : nullptr; }
  // Whether coarse silhouettes are antialiased (RenderOptions::
  // silhouette_grid, with LOD, on surfaces), and from how many rays a side.
  bool antialias() const { return lod_.has_value() && options_.silhouette_grid > 0 && !fog_; }
  int silhouette_grid() const { return antialias() ? options_.silhouette_grid : 0; }
  Cone PrimaryCone() const { return primary_cone_; }
  // The scene's background seen along world direction `dir`: the sky's
  // gradient along the camera's up vector (inline: every pixel of a block
  // its beam shows empty costs just this).
  glm::dvec3 Background(const glm::dvec3& dir) const {
    const double u = 0.5 * (glm::dot(dir, camera_.true_up()) + 1.0);
    return glm::mix(scene_.background_bottom, scene_.background_top, std::clamp(u, 0.0, 1.0));
  }
  int n2() const { return tracer_.n2(); }
  std::string SplitString() const;

 private:
  struct TraceContext;
  struct Sample;
  struct PixelValue;  // a pixel's samples, summed (tile_render.cpp)
  class TileRays;     // a tile's primary rays, a row at a time (tile_render.cpp)
  // The cone a ray carries and the level of the cell it stopped at; for
  // secondary rays of a coarse hit (a level-0 hit's are traced exactly).
  struct LodRay {
    Cone cone;
    int level = 0;
  };
  Renderer(Volume* volume, const Camera& camera, const Scene& scene, const RenderOptions& o,
           RenderTracer tracer, GridTransform xf)
      : volume_(volume), camera_(camera), scene_(scene), options_(o), tracer_(tracer), xf_(xf) {}

  // renderer.cpp: primary rays and the pixel loop.
  // Shades the primary ray `wr` (Camera::PixelRay of the sample's position).
  // `start`: the pixel's block's beam StartPlane (null: none); a block whose
  // beam meets nothing (s_min == +inf) is written by RenderTile without it.
  // `cone`: with LOD, the ray's cone (null: primary_cone_).
  void ShadePixel(const WorldRay& wr, TraceContext& cx, Sample* s,
                  const StartPlane* start = nullptr, const Cone* cone = nullptr) const;
  // The planar depth and world position of `s`'s hit (s->z) along `wr`.
  void SetHitGeometry(const WorldRay& wr, Sample* s) const;
  // The LOD level of the first stop of the primary ray `wr` with `cone`
  // (-1: a miss), without shading; *t (optional) its ray parameter.
  int PrimaryStopLevel(const WorldRay& wr, const Cone& cone, TraceContext& cx,
                       double* t = nullptr) const;

  // tile_render.cpp: the tile loop.
  // The beam StartPlane of each beam block of `rect`, row-major.
  std::vector<StartPlane> BeamPlanes(const TileRect& rect) const;
  // Shades pixel (px, py) of the tile (all its samples) into *value.
  Status ShadeTilePixel(int px, int py, TileRays& rays, TraceContext& cx, PixelValue* value) const;
  // Every pixel of the tile, waiting for each brick.
  Status ShadeTileWaiting(const TileRect& rect, TileRays& rays, TraceContext& cx,
                          TileBuffer* buf, std::vector<int8_t>* levels) const;
  // Every pixel of the tile, putting aside those whose bricks are not in
  // memory (RenderOptions::read_ahead) and shading them in later passes.
  Status ShadeTileDeferred(const TileRect& rect, TileRays& rays, TraceContext& cx,
                           LendingBrickTable* table, TileBuffer* buf,
                           std::vector<int8_t>* levels) const;
  // The silhouette pixels of the tile (antialias()), shaded again from
  // sub-pixel rays. `levels`: each pixel's stop level (-1: a miss).
  Status RefineSilhouettes(const TileRect& rect, const std::vector<int8_t>& levels,
                           TraceContext& cx, TileBuffer* buf) const;
  // Writes `value` as pixel (px, py) of `buf`.
  void WritePixel(const PixelValue& value, int px, int py, TileBuffer* buf) const;
  // The beam corner rays (grid space) of pixels [x0, x1) x [y0, y1).
  BeamCorners BlockCorners(double x0, double y0, double x1, double y1) const;

  // surface.cpp: hits and surfaces.
  // The grid-space ray of every secondary ray: from grid point p_g along
  // world direction dir_w; with `lift_normal` (a world unit normal), the
  // origin moves kSurfaceOffsetVoxels voxels along it first.
  Ray SpawnRay(const glm::dvec3& p_g, const glm::dvec3& dir_w,
               const glm::dvec3* lift_normal = nullptr, double lift_scale = 1.0) const;
  // The first hit along gr (after the run of voxels the ray starts in, if
  // skip_start_run); with `attrs`, also its attributes, read while the
  // traversal pins the brick. False on a miss or an error (cx.failed()).
  // `start`: a StartPlane gr satisfies (primary rays of a beam block).
  bool FindHit(const Ray& gr, bool skip_start_run, TraceContext& cx, Hit* hit,
               VoxelAttributes* attrs = nullptr, const StartPlane* start = nullptr) const;
  // Where surface shading wants the hit's attributes: `a`, or nullptr when
  // the scene needs none.
  VoxelAttributes* SurfaceAttrs(VoxelAttributes* a) const { return needs_attributes_ ? a : nullptr; }
  // `level`: the hit is a cell of that LOD level (its voxel in that grid).
  glm::dvec3 WorldNormal(const Ray& gr, const Hit& h, const VoxelAttributes& a,
                         int level = 0) const;
  // The shading normal of a level-0 hit at grid point p_g (index space, not
  // unit): the stored normals of the occupied voxels among the 3x3x3 around
  // the voxel whose centre is nearest p_g, weighted by the quadratic
  // B-spline of their centres' offsets from p_g (smooth across voxels,
  // unoccupied voxels left out); the hit voxel's own `a` where they cancel.
  // An error (a brick not read) goes to cx.
  glm::dvec3 SmoothNormal(const glm::dvec3& p_g, const Hit& h, const VoxelAttributes& a,
                          TraceContext& cx) const;
  // `attrs`: the hit voxel's attributes (default ones when the scene needs
  // none: unlit, no stored colour, no normal layer).
  glm::dvec3 ShadeSurface(const Ray& gr, const glm::dvec3& dir_w, const Hit& h,
                          const VoxelAttributes& attrs, int depth, TraceContext& cx,
                          glm::dvec3* normal_out, const LodRay* lod = nullptr) const;
  // The colour seen along secondary ray gr (world direction dir_w).
  glm::dvec3 Radiance(const Ray& gr, const glm::dvec3& dir_w, int depth, int kind,
                      TraceContext& cx) const;
  // The colour seen through the object that refracted ray gr enters at
  // world point origin_w (the start of gr).
  glm::dvec3 Refract(const Ray& gr, const glm::dvec3& origin_w, const glm::dvec3& dir_w,
                     int depth, TraceContext& cx) const;
  bool Occluded(const Ray& gr, double t_max, TraceContext& cx) const;

  // lod_render.cpp: level-of-detail versions of the above (render/lod.h).
  // The first hit along gr with the cone; *level its LOD level.
  bool FindHitLod(const Ray& gr, const Cone& cone, bool skip_start_run, TraceContext& cx, Hit* hit,
                  int* level, VoxelAttributes* attrs, const StartPlane* start = nullptr) const;
  bool OccludedLod(const Ray& gr, double t_max, const Cone& cone, TraceContext& cx) const;
  // The picking layers of a primary sample `s` of ray `wr` that stopped at a
  // coarse cell, traced exactly (level 0) when voxel or position is asked
  // for: its voxel, z, depth and position are the base voxel's (z = inf: no
  // voxel along the ray), colour and normal stay the pyramid's.
  void PickExactly(const WorldRay& wr, TraceContext& cx, Sample* s, const StartPlane* start) const;
  glm::dvec3 RadianceLod(const Ray& gr, const glm::dvec3& dir_w, int depth, int kind,
                         const Cone& cone, TraceContext& cx) const;
  // The cone of a secondary ray leaving a hit at ray parameter t of a ray with `cone`.
  static Cone SecondaryCone(const Cone& cone, double t) { return Cone{cone.Width(t), cone.spread}; }

  // fog.cpp: volumes.
  // `cone`: trace with LOD (nullptr: exactly). `start` (may be null): the
  // primary ray's beam StartPlane (no fog before it in the base volume).
  // *transmittance: per channel (fog_material.h: RGB extinction).
  glm::dvec3 Fog(const Ray& gr, TraceContext& cx, glm::dvec3* transmittance, double* first_t,
                 const Cone* cone = nullptr, const StartPlane* start = nullptr) const;
  // The density (and, with `temperature`, the temperature) of fog voxel h;
  // *uniform_levels (when given): see Volume::PinnedDensity (-1: not known,
  // always so with a temperature). Defined inline in fog.cpp, its only
  // caller (the walks' visitors call it for every cell).
  bool Density(const Hit& h, TraceContext& cx, double* rho, Volume* volume = nullptr,
               double* temperature = nullptr, int* uniform_levels = nullptr) const;
  glm::dvec3 Transmittance(const Ray& gr, double t_max, TraceContext& cx,
                           const Cone* cone = nullptr) const;
  // Walks the fog along gr from t = 0 to t_max (cone: with LOD), calling
  // seg(t0, t1, rho) -> bool (false: stop) for each occupied cell, or block
  // of cells of one density, in order; t1 may pass t_max.
  template <class Seg>
  void WalkFog(const Ray& gr, double t_max, const Cone* cone, TraceContext& cx, Seg&& seg) const;
  // The light reaching fog at grid point p_g (cone: with LOD), through
  // transmittance rays to the shadowing lights; with `view_w` (the world
  // direction towards the camera) each light weighted by the phase function.
  glm::dvec3 LightAtPoint(const glm::dvec3& p_g, TraceContext& cx, const Cone* cone,
                          const glm::dvec3* view_w = nullptr, double start_width = 0.0) const;
  // The light reaching fog at ray parameter t of primary ray gr, for light
  // samples h apart there: interpolated on `cache`'s lattice
  // (render/internal/fog_light.h) unless volume.light_lattice is off;
  // *max_step: the largest spacing to the next sample that it allows
  // (world units; infinite where it traced its own transmittance rays).
  glm::dvec3 LightInFog(const Ray& gr, double t, double h, TraceContext& cx, const Cone* cone,
                        render_internal::FogLightCache* cache, double* max_step) const;
  // The light at p_g interpolated on the lattice of spacing 2^level voxels:
  // false when the block's corners differ too much to interpolate; *ok
  // false when the frame failed.
  bool LatticeLight(const glm::dvec3& p_g, int level, TraceContext& cx, const Cone* cone,
                    render_internal::FogLightCache* cache, glm::dvec3* out, bool* ok) const;
  // The same on the light-space lattice of columns_ (one directional light).
  bool ColumnLight(const glm::dvec3& p_g, int level, TraceContext& cx,
                   render_internal::FogLightCache* cache, glm::dvec3* out, bool* ok) const;
  // Optical depths along gr (cone: with LOD) from depth `depth0` at t = 0:
  // out[q] at t = (q + 1) dt, q < count. False when the frame failed.
  bool DepthsAlong(const Ray& gr, double dt, int count, const glm::dvec3& depth0, const Cone& cone,
                   TraceContext& cx, glm::dvec3* out) const;

  // tracer_'s occupied box (options_.clip_to_occupied), on `t` too.
  void ApplyOccupiedBox(RenderTracer* t) const;

  Volume* volume_;
  Camera camera_;
  Scene scene_;
  RenderOptions options_;
  RenderTracer tracer_;
  GridTransform xf_;
  RenderPasses passes_;
  bool fog_ = false;
  FogModel fog_model_{FogControls{}};  // fog: what a voxel absorbs, scatters, emits
  // Fog whose three channels are one throughout: grey fog that does not
  // emit, under white lights (Fog integrates channel 0 alone).
  bool grey_fog_ = false;
  // Fog: the light lattice's level where footprint and sample spacing allow
  // it, floor(log2(volume.light_step / kLatticeSampleSpacings))
  // (render/internal/fog_light.h).
  int lattice_level_ = 0;
  bool needs_attributes_ = true;  // surfaces: shading reads normals or colours
  // Surfaces: something reads the shading normal (a light, a reflection or
  // refraction, or the normal layer); without, hits are shaded without it.
  bool needs_normal_ = true;
  // Level sets with scene.smooth_normals: ShadeSurface interpolates normals.
  bool smooth_normals_ = false;
  double eps_t_ = 1e-9;           // t tolerance for "touching" voxels, in world units
  std::optional<LodTracer> lod_;  // --lod
  Cone primary_cone_;             // the primary rays' cone (pixel width), when lod_
  // Fog lit by one directional light with shadows: the frame of the
  // light-space lattice (render/internal/fog_light.h, FogColumnCache).
  struct LightColumns {
    bool on = false;
    glm::dvec3 n{0.0}, u{0.0}, v{0.0};  // grid space: towards the light, and across it
    glm::dvec3 travel{0.0};  // the light's direction of travel, grid units per world unit
    double voxels_per_unit = 1.0;  // |travel|
    double top = 0.0;        // the largest dot(p, n) over the grid's corners
    glm::dvec3 light{0.0};   // colour times intensity
  };
  LightColumns columns_;
};

}  // namespace vox

#endif  // VOX_RENDER_RENDERER_H_

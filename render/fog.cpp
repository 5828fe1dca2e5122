// The Renderer's fog volumes: absorption and single scattering along a
// primary ray, and the transmittance of the rays towards the lights.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "render/internal/fog_math.h"
#include "render/internal/light_along_ray.h"
#include "render/internal/tracing.h"
#include "render/renderer.h"

namespace vox {

using render_internal::ExpNeg;
using render_internal::ExpNegShare;
using render_internal::ForEachLight;
using render_internal::kInf;
using render_internal::kLatticeOffset;
using render_internal::kLatticeSampleSpacings;
using render_internal::kMaxLightLatticeLevel;
using render_internal::kMaxOpticalDepth;
using render_internal::kMaxShadowOpticalDepth;
using render_internal::LightAlongRay;

// The largest optical depth of a run of thin cells of different densities
// integrated as one (Renderer::Fog).
constexpr double kMaxThinRunDepth = 0.03;

namespace {

// Renderer::Density's way for volumes without PinnedDensity (a memory
// volume, the top pool).
[[gnu::noinline]] Status DensityOfAttributes(Volume* v, const Hit& h, double* rho,
                                             double* temperature) {
  VOX_ASSIGN_OR_RETURN(VoxelAttributes a, v->HitAttributes(h));
  *rho = a.density;
  if (temperature != nullptr) *temperature = a.temperature;
  return OkStatus();
}

}  // namespace

// The density of fog voxel `h` (stops the frame with the error on failure).
[[gnu::always_inline]] inline bool Renderer::Density(const Hit& h, TraceContext& cx, double* rho,
                                                     Volume* volume, double* temperature,
                                                     int* uniform_levels) const {
  ++cx.c->attribute_lookups;
  Volume* v = volume != nullptr ? volume : volume_;
  float d;
  int levels = -1;
  // (called by visitors: h's brick is pinned)
  if (temperature == nullptr && v->PinnedDensity(h, &d, &levels)) {
    *rho = d;
    if (uniform_levels != nullptr) *uniform_levels = levels;
    return true;
  }
  if (uniform_levels != nullptr) *uniform_levels = -1;  // (blocks of one temperature are not looked for)
  Status s = DensityOfAttributes(v, h, rho, temperature);
  if (s.ok()) return true;
  cx.Fail(s);
  return false;
}

namespace {

// Fog crosses an aligned block of voxels that are all occupied and of one
// density (the inside of a fog volume; Volume::PinnedDensity finds them in
// the brick) as one cell: the integral over the block is the same, and the
// walk leaves the block without reporting its other voxels (SkipBlock,
// core/ray.h). ExitRay gives where a walk's ray (gr, in voxels) leaves a
// cell or such a block, from its direction's reciprocals: a multiplication
// per axis instead of a division.
struct ExitRay {
  explicit ExitRay(const Ray& gr) {
    for (int a = 0; a < 3; ++a) {
      // (an axis the ray does not move along exits at +inf: its origin at
      // -inf and reciprocal +inf, so no branch per axis)
      const bool moves = gr.dir[a] != 0;
      o[a] = moves ? gr.origin[a] : -kInf;
      inv[a] = moves ? 1.0 / gr.dir[a] : kInf;
      far[a] = gr.dir[a] > 0 ? 1.0 : 0.0;
    }
  }
  // Where the ray leaves the block of 2^levels cells of level `level`
  // (cells 2^level voxels a side) that holds voxel v of that level's grid
  // (levels 0: the cell itself), at most t_end.
  double BlockExit(const glm::i64vec3& v, int level, int levels, double t_end) const {
    const int k = std::max(levels, 0);
    const double size = Pow2(level + k);
    const double tx = ((double(v.x >> k) + far[0]) * size - o[0]) * inv[0];
    const double ty = ((double(v.y >> k) + far[1]) * size - o[1]) * inv[1];
    const double tz = ((double(v.z >> k) + far[2]) * size - o[2]) * inv[2];
    return std::min({t_end, tx, ty, tz});
  }
  double o[3], inv[3], far[3];
};

// floor(log2(x)) and whether x is a power of two, for a positive x: from
// its bits when normal and finite (libm's ilogb's value, without a call).
int FloorLog2(double x, bool* power_of_two) {
  uint64_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  const int biased = int(bits >> 52) & 0x7ff;
  if (biased == 0 || biased == 0x7ff) {
    *power_of_two = x == std::ldexp(1.0, std::ilogb(x));
    return std::ilogb(x);
  }
  *power_of_two = (bits & ((uint64_t(1) << 52) - 1)) == 0;
  return biased - 1023;
}

// The light inside lattice block b at offsets f (0..1 per axis), trilinear
// in the logarithm: exact where the light decays exponentially across the
// block, as in fog of even density. False where the corners' light differs
// by more than e^kMaxLatticeLogRatio (the block straddles a shadow's edge
// or the rim of thick fog) or a corner has none where others have some
// (LatticeBlock::kSteep): the caller tries a finer block.
bool InterpolateLight(const render_internal::LatticeBlock& b, const glm::dvec3& f, glm::dvec3* out) {
  if (b.shape == render_internal::LatticeBlock::kSteep) return false;
  // A white light through grey fog: the three channels are one.
  const int channels = b.shape == render_internal::LatticeBlock::kGrey ? 1 : 3;
  for (int k = 0; k < channels; ++k) {
    if (b.dark[k]) {  // no light in this channel anywhere
      (*out)[k] = 0.0;
      continue;
    }
    (*out)[k] = std::exp(render_internal::Trilinear(b.log_light[k], f));
  }
  if (channels == 1) out->y = out->z = out->x;
  return true;
}

// e^(-tau) per channel; one exponential for grey fog's three equal channels.
glm::dvec3 TransmittanceOf(const glm::dvec3& tau) {
  if (tau.x == tau.y && tau.x == tau.z) return glm::dvec3(std::exp(-tau.x));
  return glm::exp(-tau);
}

}  // namespace

template <class Seg>
void Renderer::WalkFog(const Ray& gr, double t_max, const Cone* cone, TraceContext& cx,
                       Seg&& seg) const {
  const bool has_density = volume_->meta().has_density;
  const ExitRay exits(gr);
  Status s;
  if (cone != nullptr && !lod_->Exact(gr, *cone)) {
    // Level of detail: each coarse cell's mean density over its segment.
    s = lod_->Traverse(
        *cx.tracer, cx.lod, gr, *cone,
        [&](const LodSegment& sg) {
          if (sg.t0 >= t_max) return Visit::kStop;
          double rho = 1.0;
          int levels = -1;
          if ((sg.level > 0 || has_density) && !Density(sg.hit, cx, &rho, sg.volume, nullptr, &levels))
            return Visit::kStop;
          const double t1 = exits.BlockExit(sg.hit.voxel, sg.level, levels, sg.t_end);
          return seg(sg.t0, t1, rho) ? SkipBlock(levels) : Visit::kStop;
        },
        &cx.c->trace);
  } else {
    s = cx.tracer->Traverse(
        gr,
        [&](const Hit& h) {
          if (h.t >= t_max) return Visit::kStop;
          double rho = 1.0;
          int levels = -1;
          if (has_density && !Density(h, cx, &rho, nullptr, nullptr, &levels)) return Visit::kStop;
          const double t1 = exits.BlockExit(h.voxel, 0, levels, kInf);
          return seg(h.t, t1, rho) ? SkipBlock(levels) : Visit::kStop;
        },
        &cx.c->trace);
  }
  if (!s.ok()) cx.Fail(s);
}

glm::dvec3 Renderer::Transmittance(const Ray& gr, double t_max, TraceContext& cx,
                                   const Cone* cone) const {
  ++cx.c->rays[kRayVolume];
  const FogModel& model = fog_model_;  // per channel: opacity(rho) times each extinction
  glm::dvec3 tau(0.0);
  WalkFog(gr, t_max, cone, cx, [&](double t0, double t1, double rho) {
    tau += model.Extinction(rho) * std::max(0.0, std::min(t1, t_max) - t0);
    return std::min({tau.x, tau.y, tau.z}) <= kMaxShadowOpticalDepth;
  });
  return TransmittanceOf(tau);
}

bool Renderer::DepthsAlong(const Ray& gr, double dt, int count, const glm::dvec3& depth0,
                           const Cone& cone, TraceContext& cx, glm::dvec3* out) const {
  ++cx.c->rays[kRayVolume];
  const FogModel& model = fog_model_;
  const double t_end = count * dt;
  glm::dvec3 tau = depth0;
  int q = 0;  // the next sample, at t = (q + 1) dt
  // Beyond the optical depth at which a transmittance ray stops, the
  // samples keep the depth reached (as that ray's light would).
  if (std::min({tau.x, tau.y, tau.z}) <= kMaxShadowOpticalDepth) {
    WalkFog(gr, t_end, &cone, cx, [&](double t0, double t1, double rho) {
      for (; q < count && (q + 1) * dt <= t0; ++q) out[q] = tau;  // a gap before the cell
      const glm::dvec3 ext = model.Extinction(rho);
      const double te = std::min(t1, t_end);
      for (; q < count && (q + 1) * dt <= te; ++q) out[q] = tau + ext * ((q + 1) * dt - t0);
      tau += ext * std::max(0.0, te - t0);
      return q < count && std::min({tau.x, tau.y, tau.z}) <= kMaxShadowOpticalDepth;
    });
  }
  for (; q < count; ++q) out[q] = tau;
  return !cx.failed();
}

glm::dvec3 Renderer::LightAtPoint(const glm::dvec3& p_g, TraceContext& cx, const Cone* cone,
                                  const glm::dvec3* view_w, double start_width) const {
  const glm::dvec3 p_w = xf_.GridToWorld(p_g);
  // With a pyramid, the transmittance ray's cells widen along it (as fast as
  // the primary ray's cone, or volume.shadow_lod's rate if faster), from
  // start_width voxels (0: exact voxels) where it starts: the light's path
  // far from the point is seen coarsely, near it finely.
  Cone shadow_cone;
  const Cone* sc = nullptr;
  if (cone != nullptr) {
    shadow_cone = Cone{start_width, cone->spread};
    const double g = scene_.volume.shadow_lod;
    if (g > 0) shadow_cone.spread = std::max(shadow_cone.spread, 1.0 / (g * volume_->meta().voxel_size));
    sc = &shadow_cone;
  }
  glm::dvec3 light_in(0.0);
  ForEachLight(scene_.lights, p_w, [&](const Light& l, const glm::dvec3& to_light, double dist) {
    const glm::dvec3 tl =
        l.shadows ? Transmittance(SpawnRay(p_g, to_light), dist, cx, sc) : glm::dvec3(1.0);
    const double phase = view_w != nullptr ? fog_model_.Phase(-glm::dot(to_light, *view_w)) : 1.0;
    light_in += l.color * (l.intensity * phase) * tl;
  });
  return light_in;
}

// The lattice's least spacing in pixel footprints.
constexpr double kMinLatticeFootprints = 4.0;
// The width, in lattice spacings, at which a lattice point's transmittance
// rays start (LatticeLight).
constexpr double kLatticeStartWidth = 0.25;

glm::dvec3 Renderer::LightInFog(const Ray& gr, double t, double h, TraceContext& cx, const Cone* cone,
                                render_internal::FogLightCache* cache, double* max_step) const {
  const glm::dvec3 p_g = gr.origin + t * gr.dir;
  *max_step = kInf;
  // The lattice's spacing: the largest power of two voxels within
  // light_step / kLatticeSampleSpacings, or the power of two voxels at or
  // above kMinLatticeFootprints pixel footprints (the cone's width) where
  // that is coarser, so that neighbouring pixels share its points, and at
  // most half the sample spacing h (world units); finer where the light
  // varies too much across that block, down to kMinLatticeFootprints
  // footprints. Below that (thick fog, whose light varies within a voxel;
  // the exact frame, without a cone) each sample has its own rays.
  const double h_vox = h / volume_->meta().voxel_size;
  if (!scene_.volume.light_lattice || cone == nullptr) return LightAtPoint(p_g, cx, cone);
  const double min_spacing = kMinLatticeFootprints * std::max(1.0, cone->Width(t));
  if (!(0.5 * h_vox >= min_spacing)) return LightAtPoint(p_g, cx, cone);
  bool exact;
  const int top = std::min(kMaxLightLatticeLevel, FloorLog2(0.5 * h_vox, &exact));
  const int finest_log2 = FloorLog2(min_spacing, &exact) + (exact ? 0 : 1);  // ceil(log2)
  const int finest = std::min(top, std::max(0, finest_log2));
  for (int level = std::min(top, std::max(lattice_level_, finest)); level >= finest; --level) {
    glm::dvec3 out;
    bool ok = true;
    if (!(columns_.on ? ColumnLight(p_g, level, cx, cache, &out, &ok)
                      : LatticeLight(p_g, level, cx, cone, cache, &out, &ok)))
      continue;
    *max_step = kLatticeSampleSpacings * Pow2(level) * volume_->meta().voxel_size;
    return ok ? out : glm::dvec3(0.0);
  }
  return LightAtPoint(p_g, cx, cone);
}

bool Renderer::LatticeLight(const glm::dvec3& p_g, int level, TraceContext& cx, const Cone* cone,
                            render_internal::FogLightCache* cache, glm::dvec3* out,
                            bool* ok) const {
  const double s = Pow2(level);
  const glm::dvec3 u = (p_g - kLatticeOffset) / s - 0.5;
  const glm::dvec3 f0 = glm::floor(u);
  const glm::i64vec3 i0(f0);
  const glm::dvec3 f = u - f0;
  // A lattice point's rays start a quarter of its spacing wide: the point
  // stands for the block around it, whose finer detail the interpolation
  // does not keep either.
  const double start_width = kLatticeStartWidth * s;
  const render_internal::LatticeBlock* b =
      cache->Block(level, i0, [&](const glm::dvec3& q, glm::dvec3* log_light) {
        const glm::dvec3 l = LightAtPoint(q, cx, cone, nullptr, start_width);
        if (cx.failed()) return false;
        *log_light = glm::log(l);  // -inf where no light arrives
        return true;
      });
  *ok = b != nullptr;
  if (!*ok) return true;
  return InterpolateLight(*b, f, out);
}

bool Renderer::ColumnLight(const glm::dvec3& p_g, int level, TraceContext& cx,
                           render_internal::FogLightCache* cache, glm::dvec3* out, bool* ok) const {
  using render_internal::FogColumnCache;
  const LightColumns& lc = columns_;
  const double s = Pow2(level), inv_s = Pow2(-level);  // (exact: powers of two)
  // Column coordinates: across the light in column spacings, and the sample
  // index down from the columns' top (whole spacings above the grid).
  const double top = std::floor(lc.top * inv_s) + 1.0;
  const glm::dvec3 u((glm::dot(p_g, lc.u) - kLatticeOffset) * inv_s,
                     (glm::dot(p_g, lc.v) - kLatticeOffset) * inv_s, top - glm::dot(p_g, lc.n) * inv_s);
  const double lim = double(FogColumnCache::kMaxIndex - 2);
  if (!(std::abs(u.x) < lim && std::abs(u.y) < lim && u.z >= 0 &&
        u.z < double(FogColumnCache::kMaxSample - 2)))
    return false;
  const glm::dvec3 f0 = glm::floor(u);
  // A column's ray: from its sample `first` along the light's travel, in
  // world units (samples s voxels apart), on exact voxels: one ray serves
  // the whole column, and coarser cells would blur the fog's rim on top of
  // the interpolation across columns.
  const double dt = s / lc.voxels_per_unit;
  const Cone cone{0.0, 0.0};
  const render_internal::ColumnBlock* b = cache->columns.Block(
      level, int64_t(f0.x), int64_t(f0.y), int(f0.z),
      [&](int64_t i, int64_t j, int first, int count, const glm::dvec3& depth, glm::dvec3* samples) {
        const glm::dvec3 o = (double(i) * s + kLatticeOffset) * lc.u + (double(j) * s + kLatticeOffset) * lc.v +
                             ((top - first) * s) * lc.n;
        return DepthsAlong(Ray{o, lc.travel}, dt, count, depth, cone, cx, samples);
      });
  *ok = b != nullptr;
  if (!*ok) return true;
  if (!b->Interpolate(u - f0, out)) return false;
  *out *= lc.light;
  return true;
}


glm::dvec3 Renderer::Fog(const Ray& gr, TraceContext& cx, glm::dvec3* transmittance,
                         double* first_t, const Cone* cone, const StartPlane* start) const {
  const VolumeMedium& v = scene_.volume;
  const FogModel& model = fog_model_;  // render/fog_material.h
  const bool has_density = volume_->meta().has_density;
  const bool wants_temp = model.uses_temperature();
  glm::dvec3 tau(0.0), trans(1.0);
  glm::dvec3 scattered(0.0);
  // The light reaching the ray is sampled at points along it and
  // interpolated in between (LightAlongRay). The next sample is light_step
  // voxels on (times the cone's width with LOD), or less where the fog is
  // thick: at most light_optical_depth / sqrt(T) of the extinction of the
  // cell it starts in, T the transmittance from the camera to the sample
  // (its largest channel). What a sample interval scatters towards the camera
  // weighs T, and the interpolation's error grows as the interval's square:
  // so that intervals err alike, deep in thick fog, where little of what is
  // scattered reaches the camera, the samples lie further apart.
  const double light_step = v.light_step * volume_->meta().voxel_size;  // t is in world units
  auto step_from = [&](double t, double extinction, double seen) {
    const double h = cone != nullptr ? light_step * std::max(1.0, cone->Width(t)) : light_step;
    return extinction > 0 ? std::min(h, v.light_optical_depth / (extinction * std::sqrt(seen))) : h;
  };
  render_internal::FogLightCache local_cache;  // (a thread's own when it has one)
  render_internal::FogLightCache* cache = cx.light_cache != nullptr ? cx.light_cache : &local_cache;
  // The phase function (fog_material.h): with one light the light is
  // weighted at each sample by its angle to the ray there (the lattice
  // keeps the light unweighted); with several lights each is weighted
  // before they are summed, so every sample traces its own rays.
  const glm::dvec3 view_w = -glm::normalize(xf_.grid_to_world_linear * gr.dir);  // towards the camera
  LightAlongRay light([&](double t, double h, double* max_step) {
    if (model.isotropic()) return LightInFog(gr, t, h, cx, cone, cache, max_step);
    if (scene_.lights.size() > 1) {
      *max_step = kInf;
      return LightAtPoint(gr.origin + t * gr.dir, cx, cone, &view_w);
    }
    glm::dvec3 l = LightInFog(gr, t, h, cx, cone, cache, max_step);
    ForEachLight(scene_.lights, xf_.GridToWorld(gr.origin + t * gr.dir),
                 [&](const Light&, const glm::dvec3& to_light, double) {
                   l *= model.Phase(-glm::dot(to_light, view_w));
                 });
    return l;
  }, volume_->meta().voxel_size);
  *first_t = kInf;
  // One occupied cell [t0, t1] of medium m (per channel, FogModel::At of
  // its density and temperature): the light it scatters and the light it
  // emits, each seen through the cell up to where it arises.
  FogSample m;
  auto cell = [&](double t0, double t1) {
    if (*first_t == kInf) *first_t = t0;
    const double len = std::max(0.0, t1 - t0);
    const glm::dvec3& st = m.extinction;
    const double st_max = std::max({st.x, st.y, st.z});
    if (st_max <= 0 && !model.emits()) return true;
    const glm::dvec3 seg_tau = st * len;
    glm::dvec3 seg_trans;
    bool one_piece = false;  // seg_trans set by the light's integral
    if (passes_.scattering && st_max > 0) {
      const glm::dvec3 in_cell = light.Integrate(
          t0, t1, st, trans, [&](double t, double seen) { return step_from(t, st_max, seen); },
          &seg_trans, &one_piece);
      for (int k = 0; k < 3; ++k)
        if (st[k] > 0) scattered[k] += trans[k] * m.scattering[k] / st[k] * in_cell[k];
    }
    if (!one_piece) {
      seg_trans.x = ExpNeg(seg_tau.x);
      seg_trans.y = seg_tau.y == seg_tau.x ? seg_trans.x : ExpNeg(seg_tau.y);
      seg_trans.z = seg_tau.z == seg_tau.x ? seg_trans.x : ExpNeg(seg_tau.z);
    }
    if (model.emits())  // the integral of e^(-st s) over the cell
      for (int k = 0; k < 3; ++k)
        scattered[k] += trans[k] * m.emission[k] * len * ExpNegShare(seg_tau[k]);
    tau += seg_tau;
    trans *= seg_trans;
    return !cx.failed() && std::min({tau.x, tau.y, tau.z}) <= kMaxOpticalDepth;
  };
  // The same in a grey frame (white lights in grey fog that does not
  // emit): channel 0 alone, the same operations on it; the others are set
  // from it at the end.
  const bool grey = grey_fog_;
  auto cell_grey = [&](double t0, double t1) {
    if (*first_t == kInf) *first_t = t0;
    const double len = std::max(0.0, t1 - t0);
    const double st = m.extinction.x;
    if (st <= 0) return true;
    const double seg_tau = st * len;
    double seg_trans;
    bool one_piece = false;
    if (passes_.scattering) {
      const double in_cell = light.Integrate(
          t0, t1, st, trans.x, [&](double t, double seen) { return step_from(t, st, seen); },
          &seg_trans, &one_piece);
      scattered.x += trans.x * m.scattering.x / st * in_cell;
    }
    if (!one_piece) seg_trans = ExpNeg(seg_tau);
    tau.x += seg_tau;
    trans.x *= seg_trans;
    return !cx.failed() && tau.x <= kMaxOpticalDepth;
  };
  auto least_depth = [&] { return grey ? tau.x : std::min({tau.x, tau.y, tau.z}); };
  // Runs of cells of one density and temperature that follow each other
  // along the ray (the inside of a fog: its uniform blocks and full bricks)
  // are integrated as one cell: the integral over the run is the same, and
  // each cell's set-up (its exponentials, the light's integral) is paid
  // once per run. A cell continues the run when it starts where the run
  // ends (a voxel's entry is its neighbour's exit, up to rounding). The run
  // is closed where it would pass the optical depth at which the ray stops,
  // so the walk stops where it did cell by cell. m is the run's medium,
  // kept for the next run of the same density and temperature.
  //
  // With the level of detail on (the default frame; not the exact one), a
  // grey frame whose medium is proportional to the density (no ramp) also
  // joins thin cells of different densities, while the run's optical depth
  // stays within kMaxThinRunDepth: the run is integrated with its mean
  // density, which keeps its optical depth exact and moves where its light
  // is scattered within it by at most half of that depth (the rim of a fog
  // made from a level set is a few voxels of rising density, each its own
  // cell otherwise).
  const bool join_thin = grey && cone != nullptr && model.proportional();
  const double ext_per_rho = join_thin ? model.Extinction(1.0).x : 0.0;
  double run_t0 = 0.0, run_t1 = -kInf, run_st = 0.0;
  double run_rho = std::numeric_limits<double>::quiet_NaN(), run_temp = 0.0;
  double run_mass = 0.0;  // a joined run's sum of density times length (else 0)
  auto flush = [&] {
    if (!(run_t1 > -kInf)) return true;
    const double t0 = run_t0, t1 = run_t1;
    run_t1 = -kInf;
    if (run_mass > 0) {  // joined: its mean density (m is kept for no later run)
      const double rho = run_mass / (t1 - t0);
      model.AtGrey(rho, &m.extinction.x, &m.scattering.x);
      run_rho = std::numeric_limits<double>::quiet_NaN();
      run_mass = 0.0;
    }
    return grey ? cell_grey(t0, t1) : cell(t0, t1);
  };
  auto add = [&](double t0, double t1, double rho, double temp) {
    const bool follows = run_t1 > -kInf && std::abs(t0 - run_t1) <= 1e-12 * (1.0 + std::abs(run_t1));
    if (follows && run_mass == 0 && rho == run_rho && temp == run_temp &&
        (t1 - run_t0) * run_st + least_depth() <= kMaxOpticalDepth) {
      run_t1 = std::max(run_t1, t1);
      return true;
    }
    if (join_thin && follows && t1 > run_t1) {
      const double mass = (run_mass > 0 ? run_mass : run_rho * (run_t1 - run_t0)) + rho * (t1 - run_t1);
      if (ext_per_rho * mass <= kMaxThinRunDepth) {
        run_mass = mass;
        run_t1 = t1;
        return true;
      }
    }
    if (!flush()) return false;
    if (!(rho == run_rho && temp == run_temp)) {
      if (grey) {
        model.AtGrey(rho, &m.extinction.x, &m.scattering.x);
        run_st = m.extinction.x;
      } else {
        m = model.At(rho, temp);
        run_st = std::max({m.extinction.x, m.extinction.y, m.extinction.z});
      }
      run_rho = rho;
      run_temp = temp;
    }
    run_t0 = t0;
    run_t1 = t1;
    return true;
  };
  const ExitRay exits(gr);
  Status s;
  if (cone != nullptr && !lod_->Exact(gr, *cone)) {
    s = lod_->Traverse(
        *cx.tracer, cx.lod, gr, *cone,
        [&](const LodSegment& seg) {
          double rho = 1.0, temp = 0.0;
          int levels = -1;
          if ((seg.level > 0 || has_density || wants_temp) &&
              !Density(seg.hit, cx, &rho, seg.volume, wants_temp ? &temp : nullptr, &levels))
            return Visit::kStop;
          const double t1 = exits.BlockExit(seg.hit.voxel, seg.level, levels, seg.t_end);
          if (!add(seg.t0, t1, rho, temp)) return Visit::kStop;
          return SkipBlock(levels);
        },
        &cx.c->trace, start);
  } else {
    s = cx.tracer->Traverse(
        gr,
        [&](const Hit& h) {
          double rho = 1.0, temp = 0.0;
          int levels = -1;
          if ((has_density || wants_temp) &&
              !Density(h, cx, &rho, nullptr, wants_temp ? &temp : nullptr, &levels))
            return Visit::kStop;
          const double t1 = exits.BlockExit(h.voxel, 0, levels, kInf);
          if (!add(h.t, t1, rho, temp)) return Visit::kStop;
          return SkipBlock(levels);
        },
        &cx.c->trace, start);
  }
  if (s.ok()) {
    flush();
  } else {
    cx.Fail(s);
  }
  if (grey) {
    tau.y = tau.z = tau.x;
    scattered.y = scattered.z = scattered.x;
  }
  *transmittance = TransmittanceOf(tau);
  return scattered;
}

}  // namespace vox

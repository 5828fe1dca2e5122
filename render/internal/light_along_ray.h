// The light reaching a primary ray through fog, sampled at points along it
// and integrated between them (LightAlongRay). Private to render/: fog.cpp's
// Renderer::Fog holds one per ray.
//
// Thread safety: an instance belongs to one ray of one thread.
#ifndef VOX_RENDER_INTERNAL_LIGHT_ALONG_RAY_H_
#define VOX_RENDER_INTERNAL_LIGHT_ALONG_RAY_H_

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <glm/vec3.hpp>
#include <type_traits>
#include <utility>

#include "render/internal/fog_math.h"
#include "render/internal/tracing.h"

namespace vox::render_internal {

// The light's sampling along a primary ray (LightAlongRay::Place): how far
// the light's logarithm may bend away from the geometric interpolation over
// an interval, and how much an interval is shortened for it at most.
inline constexpr double kLightLogTolerance = 0.02;
inline constexpr double kMinLightRefinement = 0.125;
inline constexpr int kMaxLightHalvings = 3;
// The most the light's curvature bends its logarithm at an interval's
// middle (Integrate takes the bend to first order).
inline constexpr double kMaxLightCurve = 0.25;
// A sample placed at a cell's entry is evaluated this many voxels inside it
// (at most half its length): the entry lies on the fog's face, where a
// light running along the face is that of the empty voxels beside it (a
// ray on a voxel face walks the voxels on its upper side), not the fog's.
inline constexpr double kEntryInsetVoxels = 1e-3;

// A channel value's largest channel, whether its channels are equal, and
// channel k: for glm::dvec3, or for double standing for three equal ones.
inline double ChannelMax(double v) { return v; }
inline double ChannelMax(const glm::dvec3& v) { return std::max({v.x, v.y, v.z}); }
inline bool ChannelsEqual(double) { return true; }
inline bool ChannelsEqual(const glm::dvec3& v) { return v.x == v.y && v.x == v.z; }
inline double& Channel(double& v, int) { return v; }
inline double Channel(const double& v, int) { return v; }
inline double& Channel(glm::dvec3& v, int k) { return v[k]; }
inline double Channel(const glm::dvec3& v, int k) { return v[k]; }

// The light reaching a primary ray through fog, sampled at points ta < tb
// along it and interpolated in between: where both samples have light, its
// logarithm along a parabola (the chord between them, exact where the
// light is attenuated along the ray at a constant rate, as behind fog of
// even density, bent by the light's curvature measured around it: Place),
// linearly otherwise. Integrate() gives a cell's in-scattered light for
// that model (exactly for the chord, to first order in the bend), one
// sample interval at a time. Samples start where the ray enters the fog, and
// again at the first cell after a gap longer than a step; an interval chosen
// for thinner fog is cut short at the first cell of higher extinction (a ray
// entering fog through its thin rim must not carry the rim's light deep into
// the fog).
template <class LightAt>
class LightAlongRay {
 public:
  // light_at(t, h, double* max_step): the light at t, for samples h apart
  // there; *max_step the largest spacing to the next sample that this
  // sample allows (a sample read from a lattice allows a few of the
  // lattice's spacings: its values are cheap, and it stands for the light
  // no further). voxel: a voxel's length in t.
  LightAlongRay(LightAt light_at, double voxel)
      : light_at_(std::move(light_at)), inset_(kEntryInsetVoxels * voxel) {}

  // The integral over t in [t0, t1] of st e^(-st (t - t0)) L(t), per
  // channel, for a cell of extinction st_rgb (per channel; st: its
  // largest, which sets the sampling) seen through transmittance
  // entry_trans from the camera; step(t, T): the sample spacing from t,
  // where the transmittance from the camera is T (its largest channel).
  // V: glm::dvec3, or double for a grey frame (white lights in grey fog:
  // channel 0 stands for the three, and is computed as with glm::dvec3).
  // *one_piece: the cell's transmittance when it was integrated in one
  // piece (then bit for bit e^(-st_rgb (t1 - t0))), else untouched;
  // returns whether it was.
  template <class V, class Step>
  V Integrate(double t0, double t1, const V& st_rgb, const V& entry_trans, Step&& step,
              V* one_piece, bool* was_one_piece) {
    constexpr bool kGrey = std::is_same_v<V, double>;
    const double st = ChannelMax(st_rgb);
    if (t0 > tb_) {  // the fog's entry, or the first cell after a long gap
      ta_ = t0;
      seen_a_ = ChannelMax(entry_trans);
      const double h = step(t0, seen_a_);
      la_ = light_at_(Inside(t0, t1), h, &max_step_);
      max_step_a_ = max_step_;
      ext_ = st;
      has_prev_ = false;
      Place(h);
    } else if (st > ext_) {
      ext_ = st;
      const double h = std::min(step(ta_, seen_a_), max_step_a_);
      const double tc = std::max(ta_ + h, t0);
      if (tc < tb_) {
        // (the bend measured for the interval holds for its first part)
        const glm::dvec3 curve = curve_;
        SetBTo(tc, light_at_(tc > t0 ? tc : Inside(t0, t1), h, &max_step_));
        if (geometric_) curve_ = curve;
      }
    }
    V sum(0.0), trans(1.0);  // trans: the cell's transmittance from t0 to t
    double t = t0;
    int pieces = 0;
    const bool grey_cell = ChannelsEqual(st_rgb);
    while (t < t1) {
      if (t >= tb_) {
        has_prev_ = geometric_;
        prev_rate_ = rate_;
        prev_len_ = tb_ - ta_;
        ta_ = tb_;
        la_ = lb_;
        max_step_a_ = max_step_b_;
        ext_ = st;
        seen_a_ = ChannelMax(V(entry_trans * trans));
        const double h = step(ta_, seen_a_);
        Place(h);
      }
      // (a step lost below t's precision ends the cell with this interval)
      const double e = tb_ > t ? std::min(t1, tb_) : t1, len = e - t;
      const V piece_tau = st_rgb * len;
      V piece_trans;
      if constexpr (kGrey) {
        piece_trans = ExpNeg(piece_tau);
      } else {
        piece_trans.x = ExpNeg(piece_tau.x);
        piece_trans.y = grey_cell ? piece_trans.x : ExpNeg(piece_tau.y);
        piece_trans.z = grey_cell ? piece_trans.x : ExpNeg(piece_tau.z);
      }
      if (geometric_) {
        // The light at t, carried from where it was last known at its
        // decay rate (a cell's exit is the next one's entry, up to rounding).
        // A white light in grey fog: one channel computed for three.
        const int channels = kGrey || (grey_ && grey_cell) ? 1 : 3;
        V in(0.0);
        for (int k = 0; k < channels; ++k) {
          // The light's log-rate of decay along the ray from s0 to s1: the
          // chord's of the light's logarithm, -rate (s - ta) + curve/2 (s
          // - ta) (s - tb) (a straight line where curve is 0).
          const double rate = rate_[k], curve = curve_[k];
          auto chord = [&](double s0, double s1) { return rate - 0.5 * curve * (s0 + s1 - ta_ - tb_); };
          if (!(lt_ == t)) l_[k] = lt_ == -kInf ? la_[k] * ExpNeg(chord(ta_, t) * (t - ta_))
                                                : l_[k] * ExpNeg(chord(lt_, t) * (t - lt_));
          // (e^(-(tau + kappa len)) as the product of the piece's
          // transmittance and the light's decay: one exponential fewer)
          const double kappa = chord(t, e), decay = ExpNeg(kappa * len);
          const double x = Channel(piece_tau, k) + kappa * len, ex = Channel(piece_trans, k) * decay;
          Channel(in, k) = l_[k] * Channel(piece_tau, k) * ExpNegShareOf(x, ex);
          // The curve's share: curve/2 (s - t) (s - e) over the piece, to
          // first order (Place keeps the bend at the interval's middle
          // within kMaxLightCurve).
          if (curve != 0)
            Channel(in, k) += l_[k] * Channel(st_rgb, k) * (0.5 * curve) * (len * len * len) * CurveShareOf(x, ex);
          l_[k] *= decay;
        }
        if constexpr (!kGrey)
          if (channels == 1) in[1] = in[2] = in[0], l_[1] = l_[2] = l_[0];
        sum += trans * in;
        lt_ = e;
      } else {
        for (int k = 0; k < (kGrey ? 1 : 3); ++k) {
          const double w = tb_ > ta_ ? std::clamp((t + 0.5 * len - ta_) / (tb_ - ta_), 0.0, 1.0) : 0.0;
          Channel(sum, k) += Channel(trans, k) * (1.0 - Channel(piece_trans, k)) * (la_[k] + w * (lb_[k] - la_[k]));
        }
      }
      trans *= piece_trans;
      t = e;
      ++pieces;
    }
    *was_one_piece = pieces == 1;
    if (pieces == 1) *one_piece = trans;
    return sum;
  }

 private:
  // Where the light at the entry t0 of cell [t0, t1] is read.
  double Inside(double t0, double t1) const { return t0 + std::min(inset_, 0.5 * (t1 - t0)); }

  // Places the next sample h after ta_ (or as far as ta_'s sample allows),
  // or closer where the light's logarithm bends along the ray, whether the
  // samples trace their own rays or are read from a lattice: the geometric
  // interpolation is exact where it is straight, and errs by about its
  // curvature times len^2 / 8 over an interval len. The curvature is the
  // change of the light's rate from the interval before, or, on the first
  // interval of a stretch of fog, the midpoint's distance from the
  // interpolation (halved while it errs: at the light's terminator the
  // light's depth grows as the square root of the distance). The tolerance
  // grows as the transmittance from the camera falls, as the spacing does
  // (what errs is seen through it). The curvature measured is kept for the
  // interval (curve_), whose interpolation it bends.
  void Place(double h) {
    SetB(ta_ + std::min(h, max_step_a_), h);
    if (!geometric_) return;
    // (Channel 0 decides: the channels' light crosses the same fog, and a
    // grey frame places the same samples as its per-channel twin.)
    const double tol = kLightLogTolerance / seen_a_;
    if (has_prev_) {
      const double len = tb_ - ta_;
      const double bend = std::abs(rate_[0] - prev_rate_[0]) / (0.5 * (len + prev_len_));
      if (bend * len * len > 8.0 * tol)
        SetB(ta_ + std::max(kMinLightRefinement * len, std::sqrt(8.0 * tol / bend)), h);
      // The light's curvature over the interval (Integrate): the change of
      // its rate from the interval before, at most what bends the light by
      // the tolerance at the interval's middle (where the shortest interval
      // still bends more, the change measures the light's noise, not its
      // curvature).
      if (geometric_) {
        const double now = tb_ - ta_, most = 8.0 * std::min(tol, kMaxLightCurve) / (now * now);
        curve_ = glm::clamp((prev_rate_ - rate_) / (0.5 * (now + prev_len_)), -most, most);
      }
      return;
    }
    for (int i = 0; i < kMaxLightHalvings && geometric_; ++i) {
      const double tm = 0.5 * (ta_ + tb_);
      const glm::dvec3 lm = light_at_(tm, h, &max_step_);
      const double off = lm[0] > 0 ? std::log(lm[0] / la_[0]) + rate_[0] * (tm - ta_) : -kInf;
      if (std::abs(off) <= tol) {
        // The curvature of the quadratic through the three samples (at
        // most kMaxLightCurve at the middle).
        const double len = tb_ - ta_;
        for (int k = 0; k < (grey_ ? 1 : 3); ++k) {
          if (!(lm[k] > 0)) continue;
          const double mid = k == 0 ? off : std::log(lm[k] / la_[k]) + rate_[k] * (tm - ta_);
          curve_[k] = -8.0 * std::clamp(mid, -kMaxLightCurve, kMaxLightCurve) / (len * len);
        }
        if (grey_) curve_[1] = curve_[2] = curve_[0];
        return;
      }
      SetBTo(tm, lm);
    }
  }

  void SetB(double t, double h) { SetBTo(t, light_at_(t, h, &max_step_)); }
  // (max_step_: the sample's at t)
  void SetBTo(double t, const glm::dvec3& l) {
    tb_ = t;
    lb_ = l;
    max_step_b_ = max_step_;
    geometric_ = tb_ > ta_;
    // A white light in grey fog: one rate for the three channels.
    const bool grey = la_[0] == la_[1] && la_[0] == la_[2] && lb_[0] == lb_[1] && lb_[0] == lb_[2];
    for (int k = 0; k < (grey ? 1 : 3); ++k) {
      geometric_ = geometric_ && la_[k] > 0 && lb_[k] > 0;
      if (geometric_) rate_[k] = std::log(la_[k] / lb_[k]) / (tb_ - ta_);
    }
    if (grey) rate_[1] = rate_[2] = rate_[0];
    grey_ = geometric_ && grey;
    curve_ = glm::dvec3(0.0);
    lt_ = -kInf;  // l_ is recomputed from la_ at the new rates
  }

  LightAt light_at_;
  double inset_;            // kEntryInsetVoxels in t
  double max_step_ = kInf;  // the last sample's
  double max_step_a_ = kInf, max_step_b_ = kInf;  // the samples' at ta_ and tb_
  double ta_ = -kInf, tb_ = -kInf, ext_ = 0.0;  // ext_: the extinction [ta, tb] was chosen for
  double seen_a_ = 1.0;  // the transmittance from the camera at ta_
  glm::dvec3 la_{0.0}, lb_{0.0}, rate_{0.0};
  // The second derivative of the light's logarithm over [ta, tb] (Place;
  // 0: the geometric interpolation).
  glm::dvec3 curve_{0.0};
  // The light at lt_ (-inf: not known since the rates changed).
  glm::dvec3 l_{0.0};
  double lt_ = -kInf;
  bool geometric_ = false, grey_ = false;
  // The interval before [ta, tb], when it was interpolated geometrically.
  bool has_prev_ = false;
  glm::dvec3 prev_rate_{0.0};
  double prev_len_ = 0.0;
};

}  // namespace vox::render_internal

#endif  // VOX_RENDER_INTERNAL_LIGHT_ALONG_RAY_H_

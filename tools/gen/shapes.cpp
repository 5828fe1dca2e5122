// The procedural shapes of tools/gen/shapes.h.
#include "tools/gen/shapes.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#include <glm/geometric.hpp>

namespace vox::gen {
namespace {

// Radius of the unit sphere in voxels: 15/16 of the grid across.
double RadiusVoxels(uint64_t size) { return double(size) * 15.0 / 32.0; }

class Sphere : public Shape {
 public:
  explicit Sphere(double r) : r_(r) {}
  double Distance(const glm::dvec3& p) const override {
    return std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) - r_;
  }
  glm::dvec3 Normal(const glm::dvec3& p) const override {
    double l = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    return l > 0 ? p / l : glm::dvec3(0);
  }
  // Exact: the nearest and farthest points of the box from the centre. Each
  // clamped coordinate is no larger in magnitude than any point's of the box
  // (and the far corner's no smaller), and sqrt of a sum of squares rounds
  // monotonically, so no occupied voxel centre is ever refused.
  bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double band) const override {
    glm::dvec3 near = glm::clamp(glm::dvec3(0), lo, hi);
    glm::dvec3 far = glm::max(glm::abs(lo), glm::abs(hi));
    double dmin = std::sqrt(near.x * near.x + near.y * near.y + near.z * near.z) - r_;
    double dmax = std::sqrt(far.x * far.x + far.y * far.y + far.z * far.z) - r_;
    return dmin <= 0 && dmax > -band;
  }

 private:
  double r_;
};

// Two spheres of kPairRadius voxels centred half the grid apart, at index
// (-N/4, 0, 0) and (N/4, 0, 0): the same content in any grid from 2048^3 up,
// the rest of the grid empty (a sparse volume whose cost must not grow with
// its index space).
class Pair : public Shape {
 public:
  static constexpr double kPairRadius = 250;
  explicit Pair(uint64_t size) : sphere_(kPairRadius), c_(double(size) / 4, 0, 0) {}
  double Distance(const glm::dvec3& p) const override {
    return std::min(sphere_.Distance(p + c_), sphere_.Distance(p - c_));
  }
  glm::dvec3 Normal(const glm::dvec3& p) const override {
    const bool left = sphere_.Distance(p + c_) <= sphere_.Distance(p - c_);
    return left ? sphere_.Normal(p + c_) : sphere_.Normal(p - c_);
  }
  bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double band) const override {
    return sphere_.MayOccupy(lo + c_, hi + c_, band) || sphere_.MayOccupy(lo - c_, hi - c_, band);
  }

 private:
  Sphere sphere_;
  glm::dvec3 c_;
};

// splitmix64: a fixed stream, so every run builds the same waves.
uint64_t SplitMix(uint64_t* s);
double Uniform(uint64_t* s);

// The sphere's shell (the same voxels) with every voxel's normal tilted by a
// fixed pseudo-random jitter of up to kJitter per axis (about 20 degrees, at
// most 37) and a speckled colour (each channel of a sand colour scaled by
// 0.6..1): a rough surface whose attributes hardly compress, about 10 bytes
// per voxel on disk against the sphere's 1, so a store larger than RAM takes
// a tenth of the voxels and a fraction of the time to write
// (tests/render/out_of_core_long_test.cpp).
class Rough : public Sphere {
 public:
  static constexpr double kJitter = 0.35;
  using Sphere::Sphere;
  glm::dvec3 Normal(const glm::dvec3& p) const override {
    const glm::dvec3 n = Sphere::Normal(p);
    uint64_t s = Stream(p, 0);
    const glm::dvec3 j(2 * Uniform(&s) - 1, 2 * Uniform(&s) - 1, 2 * Uniform(&s) - 1);
    const glm::dvec3 m = n + kJitter * j;
    const double l = glm::length(m);
    return l > 0 ? m / l : n;
  }
  bool HasColor() const override { return true; }
  glm::dvec3 Color(const glm::dvec3& p) const override {
    uint64_t s = Stream(p, 1);
    const double a = 0.6 + 0.4 * Uniform(&s), b = 0.6 + 0.4 * Uniform(&s), c = 0.6 + 0.4 * Uniform(&s);
    return glm::dvec3(0.85 * a, 0.75 * b, 0.6 * c);
  }

 private:
  // Voxel centres are integer points: one stream per voxel and attribute.
  static uint64_t Stream(const glm::dvec3& p, uint64_t attribute) {
    return uint64_t(std::llround(p.x)) * 0x9E3779B97F4A7C15ull ^
           uint64_t(std::llround(p.y)) * 0xC2B2AE3D27D4EB4Full ^
           uint64_t(std::llround(p.z)) * 0x165667B19E3779F9ull ^ attribute * 0xD6E8FEB86659FD93ull;
  }
};

// splitmix64: a fixed stream, so every run builds the same waves.
uint64_t SplitMix(uint64_t* s) {
  uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
double Uniform(uint64_t* s) { return double(SplitMix(s) >> 11) * 0x1.0p-53; }

// f(p) = |p| - r - sum_i a_i sin(k_i . p + phi_i) in voxel units. Each wave's
// slope a_i |k_i| is kWaveSlope, so f is (1 + S)-Lipschitz with S = waves *
// kWaveSlope < 1, and 1 - S <= |grad f| <= 1 + S.
class Bumpy : public Shape {
 public:
  static constexpr int kOctaves = 7, kWavesPerOctave = 3;
  static constexpr double kWaveSlope = 0.04, kLongestWavelength = 0.4;  // world units

  Bumpy(double r, double voxel_size) : r_(r) {
    uint64_t seed = 0x766f782d67656e31ull;  // "vox-gen1"
    for (int o = 0; o < kOctaves; ++o) {
      for (int w = 0; w < kWavesPerOctave; ++w) {
        // A uniform direction on the unit sphere, a wavelength, a phase.
        double z = 2 * Uniform(&seed) - 1, t = 2 * std::numbers::pi * Uniform(&seed);
        double s = std::sqrt(std::max(0.0, 1 - z * z));
        glm::dvec3 dir(s * std::cos(t), s * std::sin(t), z);
        double kw = 2 * std::numbers::pi / (kLongestWavelength / double(1 << o));  // world
        Wave v;
        v.k = dir * (kw * voxel_size);            // per voxel
        v.a = kWaveSlope / (kw * voxel_size);     // voxels: a |k| = kWaveSlope
        v.phase = 2 * std::numbers::pi * Uniform(&seed);
        waves_.push_back(v);
      }
    }
    slope_ = kWaveSlope * double(waves_.size());
  }

  double Distance(const glm::dvec3& p) const override {
    glm::dvec3 g;
    double f = Eval(p, &g);
    double gl = glm::length(g);
    return gl > 1e-9 ? f / gl : f;
  }
  glm::dvec3 Normal(const glm::dvec3& p) const override {
    glm::dvec3 g;
    Eval(p, &g);
    double gl = glm::length(g);
    return gl > 0 ? g / gl : glm::dvec3(0);
  }
  // Lipschitz bound: f varies by at most (1 + S) h over the box's half
  // diagonal h from its centre, and an occupied point has f in
  // (-band |grad f|, 0], inside (-band (1 + S), 0].
  bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double band) const override {
    glm::dvec3 c = (lo + hi) * 0.5;
    double h = glm::length(hi - lo) * 0.5;
    double fc = Value(c);
    double spread = (1 + slope_) * h + 1e-9 * (1 + std::abs(fc) + r_);
    return fc - spread <= 0 && fc + spread > -band * (1 + slope_);
  }

 private:
  struct Wave {
    glm::dvec3 k;
    double a = 0, phase = 0;
  };
  double Value(const glm::dvec3& p) const {
    double d = 0;
    for (const Wave& w : waves_) d += w.a * std::sin(glm::dot(w.k, p) + w.phase);
    return glm::length(p) - r_ - d;
  }
  double Eval(const glm::dvec3& p, glm::dvec3* grad) const {
    double d = 0;
    glm::dvec3 gd(0);
    for (const Wave& w : waves_) {
      double arg = glm::dot(w.k, p) + w.phase;
      d += w.a * std::sin(arg);
      gd += w.k * (w.a * std::cos(arg));
    }
    double l = glm::length(p);
    *grad = (l > 0 ? p / l : glm::dvec3(0)) - gd;
    return l - r_ - d;
  }

  double r_;
  double slope_ = 0;
  std::vector<Wave> waves_;
};

// A scalar field: a fog volume whose voxels are occupied where Density > 0.
class Field : public Shape {
 public:
  double Distance(const glm::dvec3& p) const override { return -Density(p); }
  glm::dvec3 Normal(const glm::dvec3&) const override { return glm::dvec3(0); }
  bool IsField() const override { return true; }
};

// 1 - |p|^2 / r^2 inside the ball of radius r voxels.
class FogBall : public Field {
 public:
  explicit FogBall(double r) : r_(r) {}
  double Density(const glm::dvec3& p) const override {
    return 1.0 - (p.x * p.x + p.y * p.y + p.z * p.z) / (r_ * r_);
  }
  // Exact: the box's point nearest the centre (as Sphere::MayOccupy).
  bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double) const override {
    const glm::dvec3 near = glm::clamp(glm::dvec3(0), lo, hi);
    return Density(near) > 0;
  }

 private:
  double r_;
};

// (n(p) - kThreshold) / (1 - kThreshold) where n = 0.5 + sum of plane waves
// exceeds kThreshold (shapes.h). n is L-Lipschitz with L = sum a_i |k_i|.
class Noise : public Field {
 public:
  static constexpr int kOctaves = 6, kWavesPerOctave = 3;
  static constexpr double kLongestWavelength = 0.5, kThreshold = 0.6;  // world units; n

  explicit Noise(double voxel_size) {
    uint64_t seed = 0x766f782d666f6731ull;  // "vox-fog1"
    double octave_sum = 0;
    for (int o = 0; o < kOctaves; ++o) octave_sum += 1.0 / double(1 << o);
    const double a0 = 0.5 / (kWavesPerOctave * octave_sum);  // the amplitudes add up to 0.5
    for (int o = 0; o < kOctaves; ++o) {
      for (int w = 0; w < kWavesPerOctave; ++w) {
        const double z = 2 * Uniform(&seed) - 1, t = 2 * std::numbers::pi * Uniform(&seed);
        const double s = std::sqrt(std::max(0.0, 1 - z * z));
        const glm::dvec3 dir(s * std::cos(t), s * std::sin(t), z);
        const double kw = 2 * std::numbers::pi / (kLongestWavelength / double(1 << o));  // world
        Wave v;
        v.k = dir * (kw * voxel_size);  // per voxel
        v.a = a0 / double(1 << o);
        v.phase = 2 * std::numbers::pi * Uniform(&seed);
        waves_.push_back(v);
        lipschitz_ += v.a * kw * voxel_size;
      }
    }
  }
  double Density(const glm::dvec3& p) const override {
    return (Value(p) - kThreshold) / (1 - kThreshold);
  }
  bool MayOccupy(const glm::dvec3& lo, const glm::dvec3& hi, double) const override {
    const double h = glm::length(hi - lo) * 0.5;
    return Value((lo + hi) * 0.5) + lipschitz_ * h + 1e-9 > kThreshold;
  }

 private:
  struct Wave {
    glm::dvec3 k;
    double a = 0, phase = 0;
  };
  double Value(const glm::dvec3& p) const {
    double n = 0.5;
    for (const Wave& w : waves_) n += w.a * std::sin(glm::dot(w.k, p) + w.phase);
    return n;
  }
  std::vector<Wave> waves_;
  double lipschitz_ = 0;
};

}  // namespace

bool Shape::Voxel(const glm::dvec3& p, double band, VoxelAttributes* attr) const {
  if (IsField()) {
    const double density = Density(p);
    if (!(density > 0)) return false;
    if (attr != nullptr) attr->density = float(density);
    return true;
  }
  const double d = Distance(p);
  if (!(d > -band && d <= 0)) return false;
  if (attr != nullptr) {
    attr->normal = glm::vec3(Normal(p));
    if (HasColor()) attr->color = glm::vec3(Color(p));
  }
  return true;
}

const std::vector<std::string>& ShapeNames() {
  static const std::vector<std::string> names = {"sphere", "bumpy", "rough", "pair", "fog",
                                                 "noise"};
  return names;
}

double VoxelSize(uint64_t size) { return 32.0 / (15.0 * double(size)); }

StatusOr<std::unique_ptr<Shape>> MakeShape(const std::string& name, uint64_t size) {
  if (name == "sphere") return std::unique_ptr<Shape>(new Sphere(RadiusVoxels(size)));
  if (name == "pair") {
    if (size < 2048)
      return InvalidArgumentError("shape 'pair' needs --size 2048 or more (two spheres of " +
                                  std::to_string(int(Pair::kPairRadius)) + " voxels radius, half the grid apart)");
    return std::unique_ptr<Shape>(new Pair(size));
  }
  if (name == "rough") return std::unique_ptr<Shape>(new Rough(RadiusVoxels(size)));
  if (name == "bumpy")
    return std::unique_ptr<Shape>(new Bumpy(RadiusVoxels(size), VoxelSize(size)));
  if (name == "fog") return std::unique_ptr<Shape>(new FogBall(RadiusVoxels(size)));
  if (name == "noise") return std::unique_ptr<Shape>(new Noise(VoxelSize(size)));
  std::string known;
  for (const std::string& n : ShapeNames()) known += (known.empty() ? "" : ", ") + n;
  return InvalidArgumentError("unknown shape '" + name + "' (known: " + known + ")");
}

}  // namespace vox::gen

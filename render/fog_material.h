// Fog's shading model: what a fog voxel of density rho (and temperature T)
// absorbs, scatters and emits per RGB channel, and the direction the light
// it scatters takes (the phase function). scene.json's "volume" gives the
// controls (FogControls, parsed here; docs/fog.md):
//   "absorption": a or [r,g,b], "scattering": s or [r,g,b]   per world unit, times the density
//   "color": [r,g,b]                  tint of the scattered light
//   "ramp": [{"density":d, "color":[r,g,b], "opacity":o}, ...]
//       piecewise linear in the density (d strictly increasing; constant
//       beyond the ends): the voxel's extinction is (absorption +
//       scattering) * opacity(rho) instead of times rho, and its colour
//       tints the scattered light (and the emission, with "ramp": true)
//   "emission": {"color":[r,g,b], "intensity":I, "ramp":false}
//       radiance emitted per world unit: I * colour * opacity(rho)
//       (colour times the ramp's colour with "ramp": true)
//   "blackbody": {"intensity":I, "kelvin_scale":k, "kelvin_offset":o,
//                 "reference_kelvin":R, "normalize":false}
//       the store's temperature (vox-ingest --temperature) as a blackbody:
//       T = o + k * value Kelvin, emitting I * rgb(T) per world unit, where
//       rgb(T) is Planck's law through the CIE 1931 observer in linear sRGB,
//       scaled so that a blackbody at R Kelvin has luminance 1 (so hotter
//       is brighter, as Planck's law says), or with "normalize": true to
//       luminance 1 at every temperature (T then sets only the hue)
//   "phase_g": g                      Henyey-Greenstein asymmetry in (-1, 1):
//       0 isotropic (the default), > 0 forward, < 0 backward scattering
//
// Thread safety: FogModel is immutable after construction.
#ifndef VOX_RENDER_FOG_MATERIAL_H_
#define VOX_RENDER_FOG_MATERIAL_H_

#include <glm/vec3.hpp>
#include <nlohmann/json_fwd.hpp>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace vox {

struct FogRampPoint {
  double density = 0.0;
  glm::dvec3 color{1.0};
  double opacity = 0.0;
};

struct FogControls {
  glm::dvec3 absorption{0.5};  // per world unit, times the density
  glm::dvec3 scattering{0.5};
  glm::dvec3 color{1.0};           // tint of the scattered light
  std::vector<FogRampPoint> ramp;  // empty: opacity(rho) = rho, colour 1
  glm::dvec3 emission_color{1.0};
  double emission_intensity = 0.0;
  bool emission_ramp = false;        // the emission's colour times the ramp's
  double blackbody_intensity = 0.0;  // 0: no blackbody emission
  double kelvin_scale = 1.0, kelvin_offset = 0.0;
  double reference_kelvin = 1500.0;
  bool blackbody_normalize = false;
  double phase_g = 0.0;
};

// The medium at one voxel, per channel, per world unit.
struct FogSample {
  glm::dvec3 extinction{0.0};  // absorption + scattering
  glm::dvec3 scattering{0.0};  // times the tint (colour, ramp colour)
  glm::dvec3 emission{0.0};    // radiance emitted per world unit
};

// The CIE 1931 XYZ of a blackbody at `kelvin` (Planck's law, 380..780 nm, in
// W sr^-1 m^-2 per nm summed over 1 nm steps; the multi-lobe fit of the CIE
// colour-matching functions by Wyman, Sloan and Shirley, 2013). 0 for T <= 0.
glm::dvec3 BlackbodyXyz(double kelvin);
// CIE XYZ to linear sRGB (D65), negative components kept.
glm::dvec3 XyzToLinearSrgb(const glm::dvec3& xyz);

// The Henyey-Greenstein phase function per steradian: (1 - g^2) /
// (4 pi (1 + g^2 - 2 g cos)^1.5), cos the cosine between the light's travel
// direction and the scattered direction. Integrates to 1 over the sphere.
double HenyeyGreenstein(double g, double cos_theta);

class FogModel {
 public:
  explicit FogModel(const FogControls& c);

  FogSample At(double rho, double temperature) const;
  // At's channel 0, extinction and scattering (all three channels when
  // grey()): the same operations, without the others.
  void AtGrey(double rho, double* extinction, double* scattering) const;
  // The extinction alone (transmittance rays).
  glm::dvec3 Extinction(double rho) const { return sigma_t_ * Opacity(rho); }
  // opacity(rho): rho without a ramp.
  double Opacity(double rho) const;
  // The phase function relative to isotropic scattering (4 pi times it: 1
  // everywhere for g = 0); cos_theta between the light's travel direction
  // and the direction towards the camera.
  double Phase(double cos_theta) const {
    return isotropic_ ? 1.0 : 4.0 * kPi * HenyeyGreenstein(g_, cos_theta);
  }
  bool isotropic() const { return isotropic_; }
  bool uses_temperature() const { return blackbody_ > 0; }
  bool emits() const { return emits_; }
  bool scatters() const { return scatters_; }
  // Every density's medium has three equal channels and emits nothing.
  bool grey() const { return grey_; }
  // The medium is the density times a fixed medium (no ramp).
  bool proportional() const { return c_.ramp.empty(); }
  // Linear sRGB of the blackbody at `kelvin` as the controls scale it.
  glm::dvec3 Blackbody(double kelvin) const;

  static constexpr double kPi = 3.14159265358979323846;

 private:
  glm::dvec3 RampColor(double rho) const;

  FogControls c_;
  glm::dvec3 sigma_t_{0.0}, albedo_{0.0};  // albedo_: scattering / extinction * colour
  double g_ = 0.0, blackbody_ = 0.0, reference_y_ = 1.0;
  bool isotropic_ = true, emits_ = false, scatters_ = false, grey_ = false;
  std::vector<glm::dvec3> table_;  // Blackbody at kTableStep K steps
  static constexpr double kTableStep = 10.0, kTableMax = 40000.0;
};

// Reads the shading controls of scene.json's "volume" object `v` into
// `out` (keys absent keep their values); errors name `file` and the field.
Status ParseFogControls(const nlohmann::json& v, std::string_view file, FogControls* out);
// The keys ParseFogControls reads.
inline constexpr std::string_view kFogControlKeys[] = {"absorption", "scattering", "color",  "ramp",
                                                       "emission",   "blackbody",  "phase_g"};
// The controls as scene.json's "volume" keys, merged into `v`.
void FogControlsToJson(const FogControls& c, nlohmann::json* v);

}  // namespace vox

#endif  // VOX_RENDER_FOG_MATERIAL_H_

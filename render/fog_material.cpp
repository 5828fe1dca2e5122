// Fog's shading model and its scene.json controls. See fog_material.h.
#include "render/fog_material.h"

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <nlohmann/json.hpp>

#include "render/json_fields.h"

namespace vox {
namespace {

namespace jf = json_fields;
using nlohmann::json;

// One lobe of the colour-matching fit: a Gaussian with different widths
// below and above its centre.
double Lobe(double lambda, double mu, double s_lo, double s_hi) {
  const double s = lambda < mu ? s_lo : s_hi;
  const double x = (lambda - mu) / s;
  return std::exp(-0.5 * x * x);
}

// The CIE 1931 2-degree colour-matching functions at `nm`, by the
// multi-lobe fit of Wyman, Sloan and Shirley (JCGT 2(2), 2013).
glm::dvec3 Cmf(double nm) {
  const double x = 1.056 * Lobe(nm, 599.8, 37.9, 31.0) + 0.362 * Lobe(nm, 442.0, 16.0, 26.7) -
                   0.065 * Lobe(nm, 501.1, 20.4, 26.2);
  const double y = 0.821 * Lobe(nm, 568.8, 46.9, 40.5) + 0.286 * Lobe(nm, 530.9, 16.3, 31.1);
  const double z = 1.217 * Lobe(nm, 437.0, 11.8, 36.0) + 0.681 * Lobe(nm, 459.0, 26.0, 13.8);
  return {x, y, z};
}

Status ReadRgbOrScalar(const json& v, std::string_view key, std::string_view file,
                       glm::dvec3* out) {
  auto it = v.find(key);
  if (it == v.end()) return OkStatus();
  const std::string field = jf::Join("volume", key);
  if (it->is_number()) {
    double d = 0;
    VOX_RETURN_IF_ERROR(jf::ReadNumber(*it, file, field, &d));
    *out = glm::dvec3(d);
  } else {
    VOX_RETURN_IF_ERROR(jf::ReadVec3(*it, file, field, out));
  }
  for (int k = 0; k < 3; ++k)
    if ((*out)[k] < 0) return jf::FieldError(file, field, "must not be negative");
  return OkStatus();
}

Status NonNegative(const json& obj, std::string_view key, std::string_view file,
                   const std::string& prefix, double* out) {
  VOX_RETURN_IF_ERROR(jf::GetNumber(obj, key, file, prefix, false, out));
  if (*out < 0) return jf::FieldError(file, jf::Join(prefix, key), "must not be negative");
  return OkStatus();
}

}  // namespace

glm::dvec3 BlackbodyXyz(double kelvin) {
  if (!(kelvin > 0)) return glm::dvec3(0.0);
  constexpr double h = 6.62607015e-34, c = 2.99792458e8, k = 1.380649e-23;
  glm::dvec3 xyz(0.0);
  for (int nm = 380; nm <= 780; ++nm) {
    const double l = nm * 1e-9;
    const double b = 2.0 * h * c * c / (l * l * l * l * l) / std::expm1(h * c / (l * k * kelvin));
    xyz += 1e-9 * b * Cmf(nm);  // per nm
  }
  return xyz;
}

glm::dvec3 XyzToLinearSrgb(const glm::dvec3& v) {
  return {3.2404542 * v.x - 1.5371385 * v.y - 0.4985314 * v.z,
          -0.9692660 * v.x + 1.8760108 * v.y + 0.0415560 * v.z,
          0.0556434 * v.x - 0.2040259 * v.y + 1.0572252 * v.z};
}

double HenyeyGreenstein(double g, double cos_theta) {
  const double d = 1.0 + g * g - 2.0 * g * cos_theta;
  return (1.0 - g * g) / (4.0 * FogModel::kPi * d * std::sqrt(d));
}

FogModel::FogModel(const FogControls& c) : c_(c) {
  sigma_t_ = c.absorption + c.scattering;
  for (int k = 0; k < 3; ++k)
    albedo_[k] = sigma_t_[k] > 0 ? c.scattering[k] / sigma_t_[k] * c.color[k] : 0.0;
  scatters_ = albedo_.x > 0 || albedo_.y > 0 || albedo_.z > 0;
  g_ = c.phase_g;
  isotropic_ = g_ == 0.0;
  blackbody_ = c.blackbody_intensity;
  emits_ = blackbody_ > 0 ||
           (c.emission_intensity > 0 &&
            (c.emission_color.x > 0 || c.emission_color.y > 0 || c.emission_color.z > 0));
  auto equal = [](const glm::dvec3& v) { return v.x == v.y && v.x == v.z; };
  grey_ = !emits_ && equal(sigma_t_) && equal(albedo_);
  for (const FogRampPoint& p : c.ramp) grey_ = grey_ && equal(p.color);
  if (blackbody_ > 0) {
    reference_y_ = BlackbodyXyz(c.reference_kelvin).y;
    const int n = int(kTableMax / kTableStep) + 1;
    table_.resize(size_t(n));
    for (int i = 0; i < n; ++i) {
      const glm::dvec3 xyz = BlackbodyXyz(i * kTableStep);
      glm::dvec3 rgb = glm::max(XyzToLinearSrgb(xyz), glm::dvec3(0.0));
      if (c.blackbody_normalize)
        rgb = xyz.y > 0 ? rgb / xyz.y : glm::dvec3(0.0);
      else
        rgb /= reference_y_;
      table_[size_t(i)] = rgb;
    }
  }
}

glm::dvec3 FogModel::Blackbody(double kelvin) const {
  if (table_.empty() || !(kelvin > 0)) return glm::dvec3(0.0);
  const double u = std::min(kelvin, kTableMax) / kTableStep;
  const size_t i = std::min(size_t(u), table_.size() - 2);
  const double f = u - double(i);
  return blackbody_ * (table_[i] + f * (table_[i + 1] - table_[i]));
}

double FogModel::Opacity(double rho) const {
  const auto& r = c_.ramp;
  if (r.empty()) return rho;
  if (!(rho > r.front().density)) return r.front().opacity;
  if (rho >= r.back().density) return r.back().opacity;
  auto it = std::upper_bound(r.begin(), r.end(), rho,
                             [](double d, const FogRampPoint& p) { return d < p.density; });
  const FogRampPoint &b = *it, &a = *(it - 1);
  const double f = (rho - a.density) / (b.density - a.density);
  return a.opacity + f * (b.opacity - a.opacity);
}

glm::dvec3 FogModel::RampColor(double rho) const {
  const auto& r = c_.ramp;
  if (r.empty()) return glm::dvec3(1.0);
  if (!(rho > r.front().density)) return r.front().color;
  if (rho >= r.back().density) return r.back().color;
  auto it = std::upper_bound(r.begin(), r.end(), rho,
                             [](double d, const FogRampPoint& p) { return d < p.density; });
  const FogRampPoint &b = *it, &a = *(it - 1);
  const double f = (rho - a.density) / (b.density - a.density);
  return a.color + f * (b.color - a.color);
}

void FogModel::AtGrey(double rho, double* extinction, double* scattering) const {
  const double o = Opacity(rho);
  const double rc = c_.ramp.empty() ? 1.0 : RampColor(rho).x;
  *extinction = sigma_t_.x * o;
  *scattering = *extinction * albedo_.x * rc;
}

FogSample FogModel::At(double rho, double temperature) const {
  FogSample s;
  const double o = Opacity(rho);
  const glm::dvec3 rc = RampColor(rho);
  s.extinction = sigma_t_ * o;
  s.scattering = s.extinction * albedo_ * rc;
  if (c_.emission_intensity > 0)
    s.emission =
        c_.emission_intensity * c_.emission_color * (c_.emission_ramp ? rc : glm::dvec3(1.0)) * o;
  if (blackbody_ > 0) s.emission += Blackbody(c_.kelvin_offset + c_.kelvin_scale * temperature);
  return s;
}

Status ParseFogControls(const json& v, std::string_view file, FogControls* out) {
  VOX_RETURN_IF_ERROR(ReadRgbOrScalar(v, "absorption", file, &out->absorption));
  VOX_RETURN_IF_ERROR(ReadRgbOrScalar(v, "scattering", file, &out->scattering));
  VOX_RETURN_IF_ERROR(jf::GetColor(v, "color", file, "volume", &out->color));
  if (auto it = v.find("ramp"); it != v.end()) {
    if (!it->is_array() || it->empty())
      return jf::FieldError(file, "volume.ramp", "must be a non-empty array of control points");
    out->ramp.clear();
    for (size_t i = 0; i < it->size(); ++i) {
      const std::string p = "volume.ramp[" + std::to_string(i) + "]";
      const json& o = (*it)[i];
      if (!o.is_object()) return jf::FieldError(file, p, "must be an object");
      VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(o, {"density", "color", "opacity"}, file, p));
      if (!o.contains("density")) return jf::FieldError(file, p + ".density", "is missing");
      FogRampPoint r;
      VOX_RETURN_IF_ERROR(jf::GetNumber(o, "density", file, p, true, &r.density));
      r.opacity = r.density;  // by default the density itself
      VOX_RETURN_IF_ERROR(jf::GetColor(o, "color", file, p, &r.color));
      VOX_RETURN_IF_ERROR(NonNegative(o, "opacity", file, p, &r.opacity));
      if (!out->ramp.empty() && !(r.density > out->ramp.back().density))
        return jf::FieldError(file, p + ".density", "must be above the previous point's");
      out->ramp.push_back(r);
    }
  }
  if (auto it = v.find("emission"); it != v.end()) {
    const std::string p = "volume.emission";
    if (!it->is_object()) return jf::FieldError(file, p, "must be an object");
    VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(*it, {"color", "intensity", "ramp"}, file, p));
    out->emission_intensity = 1.0;
    VOX_RETURN_IF_ERROR(jf::GetColor(*it, "color", file, p, &out->emission_color));
    VOX_RETURN_IF_ERROR(NonNegative(*it, "intensity", file, p, &out->emission_intensity));
    VOX_RETURN_IF_ERROR(jf::GetBool(*it, "ramp", file, p, &out->emission_ramp));
    if (out->emission_ramp && out->ramp.empty())
      return jf::FieldError(file, p + ".ramp", "needs volume.ramp");
  }
  if (auto it = v.find("blackbody"); it != v.end()) {
    const std::string p = "volume.blackbody";
    if (!it->is_object()) return jf::FieldError(file, p, "must be an object");
    VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(
        *it, {"intensity", "kelvin_scale", "kelvin_offset", "reference_kelvin", "normalize"}, file,
        p));
    out->blackbody_intensity = 1.0;
    VOX_RETURN_IF_ERROR(NonNegative(*it, "intensity", file, p, &out->blackbody_intensity));
    VOX_RETURN_IF_ERROR(jf::GetNumber(*it, "kelvin_scale", file, p, false, &out->kelvin_scale));
    VOX_RETURN_IF_ERROR(jf::GetNumber(*it, "kelvin_offset", file, p, false, &out->kelvin_offset));
    VOX_RETURN_IF_ERROR(
        jf::GetNumber(*it, "reference_kelvin", file, p, false, &out->reference_kelvin));
    if (!(out->reference_kelvin >= 500 && out->reference_kelvin <= 40000))
      return jf::FieldError(file, p + ".reference_kelvin", "must be in [500, 40000] Kelvin");
    VOX_RETURN_IF_ERROR(jf::GetBool(*it, "normalize", file, p, &out->blackbody_normalize));
  }
  VOX_RETURN_IF_ERROR(jf::GetNumber(v, "phase_g", file, "volume", false, &out->phase_g));
  if (!(out->phase_g > -1 && out->phase_g < 1))
    return jf::FieldError(file, "volume.phase_g", "must be in (-1, 1)");
  return OkStatus();
}

void FogControlsToJson(const FogControls& c, json* v) {
  auto a = [](const glm::dvec3& x) { return json::array({x.x, x.y, x.z}); };
  (*v)["absorption"] = a(c.absorption);
  (*v)["scattering"] = a(c.scattering);
  (*v)["color"] = a(c.color);
  if (!c.ramp.empty()) {
    json r = json::array();
    for (const FogRampPoint& p : c.ramp)
      r.push_back({{"density", p.density}, {"color", a(p.color)}, {"opacity", p.opacity}});
    (*v)["ramp"] = r;
  }
  if (c.emission_intensity > 0)
    (*v)["emission"] = {{"color", a(c.emission_color)},
                        {"intensity", c.emission_intensity},
                        {"ramp", c.emission_ramp}};
  if (c.blackbody_intensity > 0)
    (*v)["blackbody"] = {{"intensity", c.blackbody_intensity},
                         {"kelvin_scale", c.kelvin_scale},
                         {"kelvin_offset", c.kelvin_offset},
                         {"reference_kelvin", c.reference_kelvin},
                         {"normalize", c.blackbody_normalize}};
  (*v)["phase_g"] = c.phase_g;
}

}  // namespace vox

#include "render/scene.h"

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "core/util/file.h"
#include "render/json_fields.h"

namespace vox {
namespace {

namespace jf = json_fields;
using nlohmann::json;

Status NonNegative(std::string_view file, const std::string& field, double v) {
  if (v < 0) return jf::FieldError(file, field, "must not be negative");
  return OkStatus();
}

Status ParseMaterial(const json& m, std::string_view file, const std::string& prefix,
                     bool allow_box, Material* out) {
  if (!m.is_object()) return jf::FieldError(file, prefix, "must be an object");
  if (allow_box) {
    VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(
        m, {"box", "color", "diffuse", "specular", "shininess", "reflect", "transmit", "ior"}, file,
        prefix));
  } else {
    VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(
        m, {"color", "diffuse", "specular", "shininess", "reflect", "transmit", "ior"}, file,
        prefix));
  }
  VOX_RETURN_IF_ERROR(jf::GetColor(m, "color", file, prefix, &out->color));
  struct {
    const char* key;
    double* v;
  } nums[] = {{"diffuse", &out->diffuse},     {"specular", &out->specular},
              {"shininess", &out->shininess}, {"reflect", &out->reflect},
              {"transmit", &out->transmit},   {"ior", &out->ior}};
  for (auto& n : nums) {
    VOX_RETURN_IF_ERROR(jf::GetNumber(m, n.key, file, prefix, false, n.v));
    VOX_RETURN_IF_ERROR(NonNegative(file, jf::Join(prefix, n.key), *n.v));
  }
  if (out->reflect > 1)
    return jf::FieldError(file, jf::Join(prefix, "reflect"), "must be in [0, 1]");
  if (out->transmit > 1)
    return jf::FieldError(file, jf::Join(prefix, "transmit"), "must be in [0, 1]");
  if (out->reflect + out->transmit > 1)
    return jf::FieldError(file, jf::Join(prefix, "transmit"), "plus reflect must not exceed 1");
  if (!(out->ior > 0)) return jf::FieldError(file, jf::Join(prefix, "ior"), "must be positive");
  return OkStatus();
}

Status ParseLight(const json& l, std::string_view file, const std::string& prefix, Light* out) {
  if (!l.is_object()) return jf::FieldError(file, prefix, "must be an object");
  VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(
      l, {"type", "direction", "position", "color", "intensity", "shadows", "falloff"}, file, prefix));
  std::string type;
  VOX_RETURN_IF_ERROR(jf::GetString(l, "type", file, prefix, true, &type));
  if (type == "directional") {
    out->type = Light::Type::kDirectional;
    VOX_RETURN_IF_ERROR(jf::GetVec3(l, "direction", file, prefix, true, &out->direction));
    if (!jf::UnitVector(out->direction, &out->direction))
      return jf::FieldError(file, jf::Join(prefix, "direction"), "is the zero vector");
    for (const char* key : {"position", "falloff"})
      if (l.contains(key))
        return jf::FieldError(file, jf::Join(prefix, key), "does not apply to a directional light");
  } else if (type == "point") {
    out->type = Light::Type::kPoint;
    VOX_RETURN_IF_ERROR(jf::GetVec3(l, "position", file, prefix, true, &out->position));
    if (l.contains("direction"))
      return jf::FieldError(file, jf::Join(prefix, "direction"), "does not apply to a point light");
    std::string falloff = "inverse_square";
    VOX_RETURN_IF_ERROR(jf::GetString(l, "falloff", file, prefix, false, &falloff));
    if (falloff != "inverse_square" && falloff != "none")
      return jf::FieldError(file, jf::Join(prefix, "falloff"),
                            "is '" + falloff + "'; it must be 'inverse_square' or 'none'");
    out->falloff = falloff == "inverse_square";
  } else {
    return jf::FieldError(file, jf::Join(prefix, "type"),
                          "is '" + type + "'; it must be 'directional' or 'point'");
  }
  VOX_RETURN_IF_ERROR(jf::GetColor(l, "color", file, prefix, &out->color));
  VOX_RETURN_IF_ERROR(jf::GetNumber(l, "intensity", file, prefix, false, &out->intensity));
  VOX_RETURN_IF_ERROR(NonNegative(file, jf::Join(prefix, "intensity"), out->intensity));
  VOX_RETURN_IF_ERROR(jf::GetBool(l, "shadows", file, prefix, &out->shadows));
  return OkStatus();
}

}  // namespace

StatusOr<Scene> ParseScene(std::string_view json_text, std::string_view file) {
  VOX_ASSIGN_OR_RETURN(json j, jf::Parse(json_text, file));
  VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(j,
                                         {"background", "background_in_exr", "ambient", "lights",
                                          "material", "materials", "volume", "max_depth",
                                          "samples_per_pixel", "normals"},
                                         file, ""));
  Scene s;
  if (auto it = j.find("background"); it != j.end()) {
    if (it->is_array()) {
      VOX_RETURN_IF_ERROR(jf::ReadVec3(*it, file, "background", &s.background_top));
      s.background_bottom = s.background_top;
    } else if (it->is_object()) {
      VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(*it, {"top", "bottom"}, file, "background"));
      VOX_RETURN_IF_ERROR(jf::GetVec3(*it, "top", file, "background", true, &s.background_top));
      VOX_RETURN_IF_ERROR(
          jf::GetVec3(*it, "bottom", file, "background", true, &s.background_bottom));
    } else {
      return jf::FieldError(file, "background",
                            "must be [r,g,b] or {\"top\":[r,g,b], \"bottom\":[r,g,b]}");
    }
    for (int a = 0; a < 3; ++a)
      if (s.background_top[a] < 0 || s.background_bottom[a] < 0)
        return jf::FieldError(file, "background", "must not have negative components");
  }
  VOX_RETURN_IF_ERROR(
      jf::GetBool(j, "background_in_exr", file, "", &s.background_in_exr));
  VOX_RETURN_IF_ERROR(jf::GetColor(j, "ambient", file, "", &s.ambient));
  if (auto it = j.find("lights"); it != j.end()) {
    if (!it->is_array()) return jf::FieldError(file, "lights", "must be an array");
    s.default_lights = false;
    for (size_t i = 0; i < it->size(); ++i) {
      Light l;
      VOX_RETURN_IF_ERROR(ParseLight((*it)[i], file, "lights[" + std::to_string(i) + "]", &l));
      s.lights.push_back(l);
    }
  }
  if (auto it = j.find("material"); it != j.end())
    VOX_RETURN_IF_ERROR(ParseMaterial(*it, file, "material", false, &s.material));
  if (auto it = j.find("materials"); it != j.end()) {
    if (!it->is_array()) return jf::FieldError(file, "materials", "must be an array");
    for (size_t i = 0; i < it->size(); ++i) {
      const std::string prefix = "materials[" + std::to_string(i) + "]";
      MaterialRegion r;
      r.material = s.material;
      VOX_RETURN_IF_ERROR(ParseMaterial((*it)[i], file, prefix, true, &r.material));
      auto box = (*it)[i].find("box");
      if (box == (*it)[i].end()) return jf::FieldError(file, prefix + ".box", "is missing");
      if (!box->is_object()) return jf::FieldError(file, prefix + ".box", "must be an object");
      VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(*box, {"min", "max"}, file, prefix + ".box"));
      VOX_RETURN_IF_ERROR(jf::GetVec3(*box, "min", file, prefix + ".box", true, &r.min));
      VOX_RETURN_IF_ERROR(jf::GetVec3(*box, "max", file, prefix + ".box", true, &r.max));
      for (int a = 0; a < 3; ++a)
        if (r.min[a] > r.max[a])
          return jf::FieldError(file, prefix + ".box",
                                "has min above max on axis " + std::string(1, "xyz"[a]));
      s.regions.push_back(r);
    }
  }
  if (auto it = j.find("volume"); it != j.end()) {
    if (!it->is_object()) return jf::FieldError(file, "volume", "must be an object");
    VOX_RETURN_IF_ERROR(
        jf::CheckKnownKeys(*it, {"absorption", "scattering", "color", "ramp", "emission",
                                 "blackbody", "phase_g", "light_step", "light_optical_depth",
                                 "shadow_lod", "light_lattice"},
                           file, "volume"));
    VOX_RETURN_IF_ERROR(ParseFogControls(*it, file, &s.volume));
    VOX_RETURN_IF_ERROR(
        jf::GetNumber(*it, "light_step", file, "volume", false, &s.volume.light_step));
    if (!(s.volume.light_step > 0 && s.volume.light_step <= 1e6))
      return jf::FieldError(file, "volume.light_step", "must be in (0, 1e6] voxels");
    VOX_RETURN_IF_ERROR(jf::GetNumber(*it, "light_optical_depth", file, "volume", false,
                                      &s.volume.light_optical_depth));
    if (!(s.volume.light_optical_depth > 0 && s.volume.light_optical_depth <= 1e6))
      return jf::FieldError(file, "volume.light_optical_depth", "must be in (0, 1e6]");
    VOX_RETURN_IF_ERROR(
        jf::GetNumber(*it, "shadow_lod", file, "volume", false, &s.volume.shadow_lod));
    if (!(s.volume.shadow_lod >= 0 && s.volume.shadow_lod <= 1e6))
      return jf::FieldError(file, "volume.shadow_lod", "must be in [0, 1e6] voxels");
    VOX_RETURN_IF_ERROR(
        jf::GetBool(*it, "light_lattice", file, "volume", &s.volume.light_lattice));
  }
  std::string normals = "smooth";
  VOX_RETURN_IF_ERROR(jf::GetString(j, "normals", file, "", false, &normals));
  if (normals != "smooth" && normals != "flat")
    return jf::FieldError(file, "normals", "is '" + normals + "'; it must be 'smooth' or 'flat'");
  s.smooth_normals = normals == "smooth";
  VOX_RETURN_IF_ERROR(jf::GetInt(j, "max_depth", file, "", false, 0, 16, &s.max_depth));
  VOX_RETURN_IF_ERROR(
      jf::GetInt(j, "samples_per_pixel", file, "", false, 1, 1024, &s.samples_per_pixel));
  return s;
}

StatusOr<Scene> LoadScene(const std::string& path) {
  VOX_ASSIGN_OR_RETURN(std::string text, ReadTextFile(path));
  return ParseScene(text, path);
}

bool SceneRefracts(const Scene& scene) {
  bool transmits = scene.material.transmit > 0;
  for (const MaterialRegion& r : scene.regions) transmits = transmits || r.material.transmit > 0;
  return scene.max_depth > 0 && transmits;
}

std::string Scene::ToJson() const {
  auto v = [](const glm::dvec3& x) { return json::array({x.x, x.y, x.z}); };
  auto mat = [&](const Material& m) {
    return json{{"color", v(m.color)},
                {"diffuse", m.diffuse},
                {"specular", m.specular},
                {"shininess", m.shininess},
                {"reflect", m.reflect},
                {"transmit", m.transmit},
                {"ior", m.ior}};
  };
  json j;
  j["background"] = {{"top", v(background_top)}, {"bottom", v(background_bottom)}};
  j["background_in_exr"] = background_in_exr;
  j["ambient"] = v(ambient);
  json lights_json = json::array();
  for (const Light& l : lights) {
    json o{{"color", v(l.color)}, {"intensity", l.intensity}, {"shadows", l.shadows}};
    if (l.type == Light::Type::kDirectional) {
      o["type"] = "directional";
      o["direction"] = v(l.direction);
    } else {
      o["type"] = "point";
      o["position"] = v(l.position);
      o["falloff"] = l.falloff ? "inverse_square" : "none";
    }
    lights_json.push_back(o);
  }
  j["lights"] = lights_json;
  j["material"] = mat(material);
  json regs = json::array();
  for (const MaterialRegion& r : regions) {
    json o = mat(r.material);
    o["box"] = {{"min", v(r.min)}, {"max", v(r.max)}};
    regs.push_back(o);
  }
  if (!regions.empty()) j["materials"] = regs;
  j["volume"] = {{"light_step", volume.light_step},
                 {"light_optical_depth", volume.light_optical_depth},
                 {"shadow_lod", volume.shadow_lod},
                 {"light_lattice", volume.light_lattice}};
  j["normals"] = smooth_normals ? "smooth" : "flat";
  FogControlsToJson(volume, &j["volume"]);
  j["max_depth"] = max_depth;
  j["samples_per_pixel"] = samples_per_pixel;
  return j.dump();
}

}  // namespace vox

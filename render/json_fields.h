// Typed field readers over nlohmann::json for vox's JSON inputs (cam.json,
// scene.json): each error names the file and the field path ("scene.json:
// lights[0].color[2] must be a finite number"). Header-only: its users link
// nlohmann_json. Stateless; thread-safe.
#ifndef VOX_STORAGE_JSON_FIELDS_H_
#define VOX_STORAGE_JSON_FIELDS_H_

#include <algorithm>
#include <cmath>
#include <glm/vec3.hpp>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace vox::json_fields {

using nlohmann::json;

// `v` scaled to unit length, through its largest component first so that
// neither huge (1e200) nor tiny (1e-200) components overflow or vanish in
// the length. False for the zero vector or a non-finite one.
inline bool UnitVector(glm::dvec3 v, glm::dvec3* out) {
  const double m = std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)});
  if (!(m > 0) || !std::isfinite(m)) return false;
  v /= m;
  *out = v / std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
  return true;
}

inline Status FieldError(std::string_view file, const std::string& field, const std::string& what) {
  return InvalidArgumentError(std::string(file) + ": field '" + field + "' " + what);
}

inline std::string Join(const std::string& prefix, std::string_view key) {
  return prefix.empty() ? std::string(key) : prefix + "." + std::string(key);
}

// Parses JSON text; a syntax error names the file and the byte offset. A key
// that appears twice in one object is an error naming the key (JSON parsers
// disagree on which one wins, so the file's meaning would be ambiguous).
// The top level must be an object, or with `allow_array` an object or an
// array (a cam.json sequence).
inline StatusOr<json> Parse(std::string_view text, std::string_view file,
                            bool allow_array = false) {
  // One key set per open object (O(log n) a key); the first duplicate seen
  // is reported.
  std::vector<std::set<std::string, std::less<>>> open_objects;
  std::string duplicate;
  auto watch = [&](int /*depth*/, json::parse_event_t event, json& parsed) {
    if (event == json::parse_event_t::object_start) {
      open_objects.emplace_back();
    } else if (event == json::parse_event_t::object_end) {
      if (!open_objects.empty()) open_objects.pop_back();
    } else if (event == json::parse_event_t::key && !open_objects.empty() && parsed.is_string()) {
      auto& keys = open_objects.back();
      const std::string& k = parsed.get_ref<const std::string&>();
      if (!keys.insert(k).second && duplicate.empty()) duplicate = k;
    }
    return true;
  };
  json j = json::parse(text, watch, /*allow_exceptions=*/false);
  if (!j.is_discarded() && !duplicate.empty())
    return InvalidArgumentError(std::string(file) + ": key '" + duplicate +
                                "' appears twice in one object");
  if (j.is_discarded()) {
    // Re-parse with exceptions to learn where it failed.
    try {
      json unused = json::parse(text);
      (void)unused;
    } catch (const json::exception& e) {
      return InvalidArgumentError(std::string(file) + ": not valid JSON: " + e.what());
    }
    return InvalidArgumentError(std::string(file) + ": not valid JSON");
  }
  if (!j.is_object() && !(allow_array && j.is_array()))
    return InvalidArgumentError(std::string(file) + (allow_array
                                                         ? ": top level must be a JSON object or array"
                                                         : ": top level must be a JSON object"));
  return j;
}

inline Status CheckKnownKeys(const json& obj, std::initializer_list<std::string_view> known,
                             std::string_view file, const std::string& prefix) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    bool ok = false;
    for (std::string_view k : known) ok = ok || it.key() == k;
    if (!ok) return FieldError(file, Join(prefix, it.key()), "is not a known field");
  }
  return OkStatus();
}

inline Status ReadNumber(const json& v, std::string_view file, const std::string& field,
                         double* out) {
  if (!v.is_number()) return FieldError(file, field, "must be a number");
  double d = v.get<double>();
  if (!std::isfinite(d)) return FieldError(file, field, "must be a finite number");
  *out = d;
  return OkStatus();
}

inline Status ReadVec3(const json& v, std::string_view file, const std::string& field,
                       glm::dvec3* out) {
  if (!v.is_array() || v.size() != 3)
    return FieldError(file, field, "must be an array of 3 numbers");
  for (int a = 0; a < 3; ++a)
    VOX_RETURN_IF_ERROR(ReadNumber(v[a], file, field + "[" + std::to_string(a) + "]", &(*out)[a]));
  return OkStatus();
}

// Optional members: leave *out alone when the key is absent. Required ones
// report "is missing".
inline Status GetNumber(const json& obj, std::string_view key, std::string_view file,
                        const std::string& prefix, bool required, double* out) {
  auto it = obj.find(key);
  if (it == obj.end())
    return required ? FieldError(file, Join(prefix, key), "is missing") : OkStatus();
  return ReadNumber(*it, file, Join(prefix, key), out);
}

inline Status GetVec3(const json& obj, std::string_view key, std::string_view file,
                      const std::string& prefix, bool required, glm::dvec3* out) {
  auto it = obj.find(key);
  if (it == obj.end())
    return required ? FieldError(file, Join(prefix, key), "is missing") : OkStatus();
  return ReadVec3(*it, file, Join(prefix, key), out);
}

// An optional colour field: three numbers, none negative.
inline Status GetColor(const json& obj, std::string_view key, std::string_view file,
                       const std::string& prefix, glm::dvec3* out) {
  VOX_RETURN_IF_ERROR(GetVec3(obj, key, file, prefix, false, out));
  for (int a = 0; a < 3; ++a)
    if ((*out)[a] < 0)
      return FieldError(file, Join(prefix, key), "must not have negative components");
  return OkStatus();
}

inline Status GetInt(const json& obj, std::string_view key, std::string_view file,
                     const std::string& prefix, bool required, int64_t lo, int64_t hi, int* out) {
  auto it = obj.find(key);
  const std::string field = Join(prefix, key);
  if (it == obj.end()) return required ? FieldError(file, field, "is missing") : OkStatus();
  if (!it->is_number_integer() && !(it->is_number_float() && std::isfinite(it->get<double>()) &&
                                    std::floor(it->get<double>()) == it->get<double>()))
    return FieldError(file, field, "must be an integer");
  double d = it->get<double>();
  if (d < double(lo) || d > double(hi))
    return FieldError(
        file, field,
        "is " + it->dump() + "; it must be in " + std::to_string(lo) + ".." + std::to_string(hi));
  *out = int(d);
  return OkStatus();
}

inline Status GetBool(const json& obj, std::string_view key, std::string_view file,
                      const std::string& prefix, bool* out) {
  auto it = obj.find(key);
  if (it == obj.end()) return OkStatus();
  if (!it->is_boolean()) return FieldError(file, Join(prefix, key), "must be true or false");
  *out = it->get<bool>();
  return OkStatus();
}

inline Status GetString(const json& obj, std::string_view key, std::string_view file,
                        const std::string& prefix, bool required, std::string* out) {
  auto it = obj.find(key);
  if (it == obj.end())
    return required ? FieldError(file, Join(prefix, key), "is missing") : OkStatus();
  if (!it->is_string()) return FieldError(file, Join(prefix, key), "must be a string");
  *out = it->get<std::string>();
  return OkStatus();
}

}  // namespace vox::json_fields

#endif  // VOX_STORAGE_JSON_FIELDS_H_

// Deterministic mutation tests of the text parsers: cam.json (ParseCamera,
// LoadCamera), scene.json (ParseScene, LoadScene) and ray lines
// (ParseRayLine, then ValidateRay). Valid seed documents are damaged by a
// fixed-seed std::mt19937_64 (byte flips, deletions, insertions, truncation at
// every length, duplicated slices, values swapped for edge cases), and every
// mutant must keep the README's promise: a clear error naming the problem and
// the file, never a crash, a hang or a wrong result. A parse that succeeds
// must give a usable value: finite, within the documented ranges, and
// accepted again after ToJson().
//
// The three bugs this file found (a huge ortho_width giving non-finite rays,
// a huge light direction becoming the zero vector, text after a NUL byte in
// a ray line ignored) are fixed; their exact inputs are tests at the end.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <functional>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <iterator>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "core/ray.h"
#include "core/ray_text.h"
#include "render/camera.h"
#include "render/scene.h"

namespace vox {
namespace {

// ---------------------------------------------------------------------------
// Seed documents.

// From tests/render/camera_scene_test.cpp.
const char* const kCameraPerspective =
    R"({"position":[0,0,10], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":90, "width":4, "height":2, "projection":"perspective"})";
const char* const kCameraOrthographic =
    R"({"position":[1,2,10], "look_at":[1,2,0], "ortho_width":8, "width":8, "height":4, "projection":"orthographic"})";
const char* const kCameraMinimal =
    R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":4, "height":4})";
const char* const kCameraOblique =
    R"({"projection":"orthographic", "position":[3,-2,5], "look_at":[-1,4,0.5], "up":[0,0,1], "ortho_width":2.5, "width":640, "height":480})";

// The demo's own files (scripts/demo/), read where the source tree has them.
std::string DemoFile(const char* name) {
  const std::string path = std::string(VOX_DEMO_DIR) + "/" + name;
  std::ifstream in(path, std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.empty()) ADD_FAILURE() << "cannot read " << path;
  return text;
}

std::vector<std::string> CameraSeeds() {
  return {kCameraPerspective, kCameraOrthographic, kCameraMinimal, DemoFile("cam.json"),
          kCameraOblique};
}

// From tests/render/camera_scene_test.cpp.
const char* const kSceneFull = R"({
    "background": {"top":[1,0,0], "bottom":[0,0,1]}, "ambient":[0.1,0.1,0.1],
    "lights": [{"type":"directional", "direction":[0,-2,0], "color":[1,1,1], "intensity":2, "shadows":false},
               {"type":"point", "position":[1,2,3]}],
    "material": {"color":[1,0.5,0.25], "diffuse":0.7, "specular":0.1, "shininess":8, "reflect":0.2, "transmit":0.3, "ior":1.33},
    "materials": [{"box":{"min":[0,0,0],"max":[1,1,1]}, "reflect":0.7, "diffuse":0}],
    "volume": {"absorption":0.2, "scattering":0.7},
    "max_depth": 3, "samples_per_pixel": 4})";
const char* const kSceneNoLights = R"({"lights": []})";
// The fields the others leave out: background as one colour, a tinted
// volume, transmission, the range limits of max_depth and samples_per_pixel.
const char* const kSceneEdges =
    R"({"background":[0.2,0.3,0.4], "ambient":[0,0,0], "volume":{"absorption":0,"scattering":2,"color":[1,0.9,0.8]}, "lights":[{"type":"point","position":[0,5,0],"intensity":3,"color":[2,2,2]}], "material":{"transmit":0.5,"reflect":0.5,"ior":1.33}, "max_depth":16, "samples_per_pixel":1024})";

std::vector<std::string> SceneSeeds() {
  return {kSceneFull, kSceneNoLights, DemoFile("scene.json"), kSceneEdges};
}

// Ray lines: decimal, C99 hex floats, odd spacing, a CRLF ending.
const char* const kRaySeeds[] = {
    "1 2 3 0.1 0.2 1",
    "0x1p+0 0x1.8p+1 -0x1p-2 0x0p+0 0x1p+0 -0x1.fffffffffffffp+1023",
    "  10.5\t20 30   -1 -1 -1  ",
    "1e10 -1e-10 0 1 0 0\r\n",
    "-0 +0 .5 0x.8p1 1E3 -2.5e-3",
};

// Values swapped in for any JSON value of a seed: edges of double and int,
// things that are not JSON numbers, and every other JSON type.
const char* const kValueSwaps[] = {
    "0", "-0", "-0.0", "1", "-1", "-5", "0.5", "2.5", "180", "179.99999999999997", "360", "1e400",
    "-1e400", "1e-400", "5e-324", "1e-320", "1e200", "-1e200", "1e308", "1.7976931348623157e308",
    "99999999999999999999", "-99999999999999999999", "18446744073709551615", "9223372036854775807",
    "-9223372036854775808", "2147483648", "4294967297", "1048576", "1048577", "1e0", "16", "16.0",
    "17", "1024", "1025",
    // Not JSON numbers.
    "nan", "NaN", "-nan", "inf", "-Infinity", "0x10", "1.", ".5", "01", "+1", "1e", "--1",
    // Other JSON types.
    "\"nan\"", "\"1\"", "\"\"", "\"perspective\"", "\"orthographic\"", "\"point\"",
    "\"directional\"", "null", "true", "false", "[]", "{}", "[[[[1]]]]", "[0,0,0]", "[-0,0,0]",
    "[1,2]", "[1,2,3,4]", "[-1,-1,-1]", "[1e200,0,0]", "[1e-200,0,0]", "[5e-324,0,0]",
    "[1e308,1e308,1e308]", "[0,0,-1]", "[0,1,0]", "[nan,0,0]", "[null,null,null]", "[\"1\",2,3]",
    "{\"a\":1}", "{\"min\":[0,0,0],\"max\":[1,1,1]}"};

// Tokens swapped in for a number of a ray line.
const char* const kRayTokenSwaps[] = {
    "nan",       "-nan",   "NAN(123)", "inf",    "-inf",
    "infinity",  "1e400",  "-1e400",   "1e-400", "0x1p2000",
    "0x1p-2000", "5e-324", "-0",       "0",      "0x",
    "0x1p",      "1e",     "1..2",     "--1",    "+-1",
    "0x1.8p+1",  "1,5",    "1e+",      ".",      "-",
    "+",         "e5",     "0b1",      "1f",     "99999999999999999999999999999999999999"};

// Characters inserted by the byte-level mutations (NUL included).
using namespace std::string_view_literals;
constexpr std::string_view kJsonAlphabet = "{}[]\",:-.eE0123456789 \t\n\r\0"sv;
constexpr std::string_view kRayAlphabet = "0123456789.eEpPxX+-nNaAiIfF \t\r\n#,\0"sv;


// ---------------------------------------------------------------------------
// Value spans of a valid JSON seed, so that values can be swapped.

struct Span {
  size_t begin = 0, end = 0;  // the value's text is [begin, end)
  std::string key;            // member name holding it ("up", "lights[]"), "" at the top
};

// A small scanner for the trusted seeds above; not a validator.
class SpanScanner {
 public:
  explicit SpanScanner(const std::string& text) : t_(text) {}
  std::vector<Span> Scan() {
    Value("");
    return spans_;
  }

 private:
  void Ws() {
    while (i_ < t_.size() && std::strchr(" \t\r\n", t_[i_]) != nullptr) ++i_;
  }
  std::string String() {
    size_t b = ++i_;
    while (i_ < t_.size() && t_[i_] != '"') i_ += (t_[i_] == '\\') ? 2 : 1;
    return t_.substr(b, i_++ - b);
  }
  void Value(const std::string& key) {
    Ws();
    const size_t b = i_;
    if (t_[i_] == '{') {
      ++i_;
      Ws();
      while (t_[i_] != '}') {
        std::string k = String();
        Ws();
        ++i_;  // ':'
        Value(k);
        Ws();
        if (t_[i_] == ',') ++i_;
        Ws();
      }
      ++i_;
    } else if (t_[i_] == '[') {
      ++i_;
      Ws();
      while (t_[i_] != ']') {
        Value(key + "[]");
        Ws();
        if (t_[i_] == ',') ++i_;
        Ws();
      }
      ++i_;
    } else if (t_[i_] == '"') {
      String();
    } else {
      while (i_ < t_.size() && std::strchr(",]} \t\r\n", t_[i_]) == nullptr) ++i_;
    }
    spans_.push_back({b, i_, key});
  }

  const std::string& t_;
  size_t i_ = 0;
  std::vector<Span> spans_;
};

std::string Vec3Text(const glm::dvec3& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "[%.17g,%.17g,%.17g]", v.x, v.y, v.z);
  return buf;
}

// A seed with its value spans and the extra, field-specific swaps.
struct Seed {
  std::string text;
  std::vector<Span> spans;
  std::vector<std::pair<std::string, std::string>> keyed_swaps;  // (key, value)

  std::vector<std::string> SwapsFor(const Span& s) const {
    std::vector<std::string> out(std::begin(kValueSwaps), std::end(kValueSwaps));
    for (const auto& [key, value] : keyed_swaps)
      if (key == s.key) out.push_back(value);
    return out;
  }
};

Seed MakeSeed(const std::string& text) {
  Seed s;
  s.text = text;
  s.spans = SpanScanner(text).Scan();
  return s;
}

// Camera seeds also swap in an "up" parallel (or antiparallel, tiny, huge)
// to the view direction, position and look_at equal, and edge values of
// fov_deg, ortho_width, width and height.
Seed MakeCameraSeed(const std::string& text) {
  Seed s = MakeSeed(text);
  StatusOr<Camera> cam = ParseCamera(text, "seed.json");
  EXPECT_TRUE(cam.ok()) << cam.status().ToString();
  if (!cam.ok()) return s;
  const glm::dvec3 f = cam->forward();
  for (const glm::dvec3& up : {f, -f, 1e-3 * f, 1e300 * f, 3.0 * (cam->look_at - cam->position)})
    s.keyed_swaps.push_back({"up", Vec3Text(up)});
  s.keyed_swaps.push_back({"position", Vec3Text(cam->look_at)});
  s.keyed_swaps.push_back({"look_at", Vec3Text(cam->position)});
  for (const char* v : {"0", "-1", "-0", "1e-300", "179.999999", "-5", "180", "0.0001"})
    s.keyed_swaps.push_back({"fov_deg", v});
  for (const char* v : {"0", "-1", "-0", "1e-300", "1e-320", "1e308"})
    s.keyed_swaps.push_back({"ortho_width", v});
  for (const char* v : {"0", "-1", "-0", "-0.0", "1", "1048576", "1048577", "2.5", "1e6"}) {
    s.keyed_swaps.push_back({"width", v});
    s.keyed_swaps.push_back({"height", v});
  }
  return s;
}

// ---------------------------------------------------------------------------
// The mutator: deterministic for a given seed on every platform (it uses the
// engine's raw output, not the implementation-defined distributions).

class Mutator {
 public:
  explicit Mutator(uint64_t seed) : rng_(seed) {}

  size_t Below(size_t n) { return n == 0 ? 0 : size_t(rng_() % n); }
  bool OneIn(size_t n) { return Below(n) == 0; }

  // One random byte-level mutation of `s`.
  void MutateBytes(std::string* s, std::string_view alphabet) {
    const size_t pos = Below(s->size() + 1);
    switch (Below(6)) {
      case 0:  // flip one bit
        if (pos < s->size()) (*s)[pos] = char((*s)[pos] ^ (1 << Below(8)));
        break;
      case 1:  // overwrite with any byte
        if (pos < s->size()) (*s)[pos] = char(Below(256));
        break;
      case 2:  // delete 1..8 bytes
        if (pos < s->size()) s->erase(pos, 1 + Below(8));
        break;
      case 3:  // insert 1..4 characters of the alphabet
        for (size_t n = 1 + Below(4); n > 0; --n)
          s->insert(pos, 1, alphabet[Below(alphabet.size())]);
        break;
      case 4: {  // duplicate a slice somewhere
        if (s->empty()) break;
        const size_t a = Below(s->size());
        const std::string slice = s->substr(a, 1 + Below(64));
        s->insert(Below(s->size() + 1), slice);
        break;
      }
      case 5:  // truncate
        s->resize(pos);
        break;
    }
  }

  // Swaps 1..3 non-overlapping values of the seed for edge cases.
  std::string SwapValues(const Seed& seed) {
    std::vector<std::pair<Span, std::string>> swaps;
    for (size_t n = 1 + Below(3); n > 0; --n) {
      const Span& sp = seed.spans[Below(seed.spans.size())];
      std::vector<std::string> values = seed.SwapsFor(sp);
      // Keyed swaps are rarer in the list; give them a fair chance.
      const size_t generic = std::size(kValueSwaps);
      std::string v = (values.size() > generic && OneIn(2))
                          ? values[generic + Below(values.size() - generic)]
                          : values[Below(values.size())];
      bool overlaps = false;
      for (const auto& [other, unused] : swaps)
        overlaps = overlaps || (sp.begin < other.end && other.begin < sp.end);
      if (!overlaps) swaps.push_back({sp, v});
    }
    // Apply right to left so that earlier offsets stay valid.
    std::sort(swaps.begin(), swaps.end(),
              [](const auto& a, const auto& b) { return a.first.begin > b.first.begin; });
    std::string out = seed.text;
    for (const auto& [sp, v] : swaps) out.replace(sp.begin, sp.end - sp.begin, v);
    return out;
  }

 private:
  std::mt19937_64 rng_;
};

// Printable form of a mutant for failure messages.
std::string Quote(std::string_view s) {
  std::string out = "\"";
  for (unsigned char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += char(c);
    } else if (c >= 0x20 && c < 0x7f) {
      out += char(c);
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    }
  }
  return out + "\"";
}

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
bool NonNegative(const glm::dvec3& v) { return v.x >= 0 && v.y >= 0 && v.z >= 0; }
bool NearUnit(const glm::dvec3& v) { return Finite(v) && std::fabs(glm::length(v) - 1.0) < 1e-9; }

// Runs `parse`, turning an escaping exception into a problem description.
template <typename T>
std::optional<StatusOr<T>> NoThrow(const std::function<StatusOr<T>()>& parse,
                                   std::string* problem) {
  try {
    return parse();
  } catch (const std::exception& e) {
    *problem = std::string("exception escaped: ") + e.what();
  } catch (...) {
    *problem = "unknown exception escaped";
  }
  return std::nullopt;
}

// The promise for a failed parse: InvalidArgument, the file named, and some
// words after it that say what is wrong.
std::string ErrorProblem(const Status& s, const std::string& file) {
  if (s.code() != StatusCode::kInvalidArgument)
    return "error is not InvalidArgument: " + s.ToString();
  const size_t at = s.message().find(file);
  if (at == std::string::npos) return "error does not name the file '" + file + "': " + s.message();
  if (s.message().size() < file.size() + 12)
    return "error does not say what is wrong: " + s.message();
  return "";
}

// ---------------------------------------------------------------------------
// What a parsed camera must satisfy; "" if it does.

std::string CameraValueProblem(const Camera& parsed, const std::string& file) {
  Camera c = parsed;
  if (c.width < 1 || c.width > kMaxImageSide) return "width " + std::to_string(c.width);
  if (c.height < 1 || c.height > kMaxImageSide) return "height " + std::to_string(c.height);
  if (!Finite(c.position) || !Finite(c.look_at) || !Finite(c.up)) return "non-finite vector";
  if (c.projection == Projection::kPerspective) {
    if (!std::isfinite(c.fov_deg) || !(c.fov_deg > 0) || !(c.fov_deg < 180))
      return "fov_deg " + std::to_string(c.fov_deg);
  } else if (!std::isfinite(c.ortho_width) || !(c.ortho_width > 0)) {
    return "ortho_width " + std::to_string(c.ortho_width);
  }
  // Finalize() was done by ParseCamera; doing it again must agree.
  if (Status s = c.Finalize(file); !s.ok())
    return "a parsed camera fails Finalize(): " + s.message();
  const glm::dvec3 f = c.forward(), r = c.right(), u = c.true_up();
  if (!NearUnit(f) || !NearUnit(r) || !NearUnit(u))
    return "camera basis is not finite unit vectors";
  if (std::fabs(glm::dot(f, r)) > 1e-9 || std::fabs(glm::dot(f, u)) > 1e-9 ||
      std::fabs(glm::dot(r, u)) > 1e-9)
    return "camera basis is not orthogonal";
  if (!(glm::dot(f, c.look_at - c.position) > 0)) return "forward does not point at look_at";
  // Rays through the corners and the centre are finite and unit.
  const double w = c.width, h = c.height;
  for (const glm::dvec2& p : {glm::dvec2(0, 0), glm::dvec2(w, 0), glm::dvec2(0, h),
                              glm::dvec2(w, h), glm::dvec2(w / 2, h / 2)}) {
    const WorldRay ray = c.PixelRay(p.x, p.y);
    const std::string what = "PixelRay(" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                             ") is not a finite unit ray: origin " + Vec3Text(ray.origin) +
                             " dir " + Vec3Text(ray.dir);
    if (!Finite(ray.origin) || !NearUnit(ray.dir)) return what;
    if (!(glm::dot(ray.dir, f) > 0)) return "a pixel ray points away from the view";
  }
  // The camera's own JSON (written into EXR headers) reads back the same.
  StatusOr<Camera> again = ParseCamera(c.ToJson(), "roundtrip.json");
  if (!again.ok()) return "ToJson() does not parse back: " + again.status().message();
  if (again->position != c.position || again->look_at != c.look_at || again->up != c.up ||
      again->width != c.width || again->height != c.height || again->projection != c.projection ||
      (c.projection == Projection::kPerspective ? again->fov_deg != c.fov_deg
                                                : again->ortho_width != c.ortho_width))
    return "ToJson() reads back a different camera: " + c.ToJson() + " vs " + again->ToJson();
  return "";
}

// `accepted`, if given, tells whether the parse succeeded.
std::string CameraProblem(const std::string& text, const std::string& file,
                          bool* accepted = nullptr) {
  std::string problem;
  std::optional<StatusOr<Camera>> cam =
      NoThrow<Camera>([&] { return ParseCamera(text, file); }, &problem);
  if (!cam) return problem;
  if (accepted) *accepted = cam->ok();
  if (!cam->ok()) return ErrorProblem(cam->status(), file);
  return CameraValueProblem(**cam, file);
}

// ---------------------------------------------------------------------------
// What a parsed scene must satisfy (the ranges scene.h documents and
// scene.cpp enforces); "" if it does.

std::string MaterialProblem(const Material& m, const std::string& where) {
  if (!Finite(m.color) || !NonNegative(m.color)) return where + ".color " + Vec3Text(m.color);
  for (double v : {m.diffuse, m.specular, m.shininess, m.reflect, m.transmit, m.ior})
    if (!std::isfinite(v) || v < 0) return where + " has a negative or non-finite coefficient";
  if (m.reflect > 1 || m.transmit > 1 || m.reflect + m.transmit > 1)
    return where + " reflect + transmit exceeds 1";
  if (!(m.ior > 0)) return where + ".ior is not positive";
  return "";
}

std::string SceneValueProblem(const Scene& s) {
  if (!Finite(s.background_top) || !Finite(s.background_bottom) ||
      !NonNegative(s.background_top) || !NonNegative(s.background_bottom))
    return "background " + Vec3Text(s.background_top) + " " + Vec3Text(s.background_bottom);
  if (!Finite(s.ambient) || !NonNegative(s.ambient)) return "ambient " + Vec3Text(s.ambient);
  if (s.default_lights && !s.lights.empty()) return "default_lights with explicit lights";
  for (size_t i = 0; i < s.lights.size(); ++i) {
    const Light& l = s.lights[i];
    const std::string where = "lights[" + std::to_string(i) + "]";
    if (!Finite(l.color) || !NonNegative(l.color)) return where + ".color " + Vec3Text(l.color);
    if (!std::isfinite(l.intensity) || l.intensity < 0) return where + ".intensity";
    if (!Finite(l.position)) return where + ".position";
    // scene.h: "direction" is a unit vector.
    if (l.type == Light::Type::kDirectional && !NearUnit(l.direction))
      return where + ".direction is not a unit vector: " + Vec3Text(l.direction);
  }
  if (std::string p = MaterialProblem(s.material, "material"); !p.empty()) return p;
  for (size_t i = 0; i < s.regions.size(); ++i) {
    const std::string where = "materials[" + std::to_string(i) + "]";
    const MaterialRegion& reg = s.regions[i];
    if (!Finite(reg.min) || !Finite(reg.max) || reg.min.x > reg.max.x || reg.min.y > reg.max.y ||
        reg.min.z > reg.max.z)
      return where + ".box";
    if (std::string p = MaterialProblem(s.regions[i].material, where); !p.empty()) return p;
  }
  const VolumeMedium& v = s.volume;
  if (!Finite(v.absorption) || !NonNegative(v.absorption) || !Finite(v.scattering) ||
      !NonNegative(v.scattering))
    return "volume coefficients";
  if (!(v.phase_g > -1 && v.phase_g < 1)) return "volume.phase_g";
  if (!Finite(v.color) || !NonNegative(v.color)) return "volume.color " + Vec3Text(v.color);
  if (s.max_depth < 0 || s.max_depth > 16) return "max_depth " + std::to_string(s.max_depth);
  if (s.samples_per_pixel < 1 || s.samples_per_pixel > 1024)
    return "samples_per_pixel " + std::to_string(s.samples_per_pixel);
  // The scene's own JSON (written into EXR headers) is accepted again
  StatusOr<Scene> again = ParseScene(s.ToJson(), "roundtrip.json");
  if (!again.ok())
    return "ToJson() does not parse back: " + again.status().message();
  return "";
}

std::string SceneProblem(const std::string& text, const std::string& file,
                         bool* accepted = nullptr) {
  std::string problem;
  std::optional<StatusOr<Scene>> scene =
      NoThrow<Scene>([&] { return ParseScene(text, file); }, &problem);
  if (!scene) return problem;
  if (accepted) *accepted = scene->ok();
  if (!scene->ok()) return ErrorProblem(scene->status(), file);
  return SceneValueProblem(**scene);
}

// ---------------------------------------------------------------------------
// Ray lines.

bool SameDouble(double a, double b) {
  return (std::isnan(a) && std::isnan(b)) || std::memcmp(&a, &b, sizeof a) == 0;
}

std::string RayProblem(const std::string& line, bool* accepted = nullptr) {
  std::string problem;
  std::optional<StatusOr<Ray>> ray = NoThrow<Ray>([&] { return ParseRayLine(line); }, &problem);
  if (!ray) return problem;
  if (accepted) *accepted = ray->ok();
  if (!ray->ok()) {
    const Status& s = ray->status();
    if (s.code() != StatusCode::kInvalidArgument) return "error is not InvalidArgument";
    const std::string& m = s.message();
    if (m.find("expected 6 numbers") == std::string::npos &&
        m.find("is not a number") == std::string::npos &&
        m.find("more than 6 numbers") == std::string::npos &&
        m.find("NUL byte") == std::string::npos)
      return "error does not say what is wrong: " + m;
    return "";
  }
  // Success: the whole line is six whitespace-separated numbers, and these
  // are the numbers returned.
  std::vector<std::string> tokens;
  size_t i = 0;
  while (i < line.size()) {
    if (std::strchr(" \t\r\n\v\f", line[i]) != nullptr && line[i] != '\0') {
      ++i;
      continue;
    }
    size_t b = i;
    while (i < line.size() && (line[i] == '\0' || std::strchr(" \t\r\n\v\f", line[i]) == nullptr))
      ++i;
    tokens.push_back(line.substr(b, i - b));
  }
  std::string mismatch;
  const Ray& r = **ray;
  const double got[6] = {r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z};
  if (tokens.size() != 6)
    mismatch = "accepted a line of " + std::to_string(tokens.size()) + " tokens";
  for (size_t k = 0; k < 6 && mismatch.empty(); ++k) {
    char* end = nullptr;
    const double want = std::strtod(tokens[k].c_str(), &end);
    if (end != tokens[k].c_str() + tokens[k].size())
      mismatch = "accepted token " + std::to_string(k + 1) + " " + Quote(tokens[k]) +
                 ", which is not a number";
    else if (!SameDouble(want, got[k]))
      mismatch = "number " + std::to_string(k + 1) + " read wrongly";
  }
  if (!mismatch.empty()) return mismatch;
  // ValidateRay refuses NaN, infinities and a zero direction, with a message.
  const bool bad = !Finite(r.origin) || !Finite(r.dir) || r.dir == glm::dvec3(0.0);
  const Status v = ValidateRay(r);
  if (bad && v.ok()) return "ValidateRay accepted a non-finite or zero-direction ray";
  if (!bad && !v.ok()) return "ValidateRay refused a good ray: " + v.message();
  if (!v.ok() && v.message().find("non-finite") == std::string::npos &&
      v.message().find("zero") == std::string::npos)
    return "ValidateRay's message does not say what is wrong: " + v.message();
  return "";
}

// ---------------------------------------------------------------------------
// Runs `check` over mutants and reports the first few failures.

class Campaign {
 public:
  explicit Campaign(std::string name) : name_(std::move(name)) {}
  void Check(const std::string& input, const std::string& problem, bool accepted) {
    ++count_;
    accepted_ += accepted;
    if (problem.empty()) return;
    if (failures_.size() < 8) failures_.push_back(problem + "\n    input: " + Quote(input));
    ++failed_;
  }
  size_t count() const { return count_; }
  void Report() const {
    std::string all;
    for (const std::string& f : failures_) all += "  " + f + "\n";
    EXPECT_EQ(failed_, 0u) << name_ << ": " << failed_ << " of " << count_
                           << " mutants broke the promise; first ones:\n"
                           << all;
    std::printf("[ %s ] %zu mutants checked (%zu accepted), %zu failed\n", name_.c_str(), count_,
                accepted_, failed_);
  }

 private:
  std::string name_;
  size_t count_ = 0, accepted_ = 0, failed_ = 0;
  std::vector<std::string> failures_;
};

constexpr uint64_t kRngSeed = 0x766f782d6d757461;  // "vox-muta"
constexpr int kRandomJsonMutants = 3000;
constexpr int kRandomRayMutants = 20000;

// Truncation at every length, every single swap of the seeds' values, then
// random stacks of swaps and byte mutations.
using JsonCheck = std::function<std::string(const std::string&, const std::string&, bool*)>;

void RunJsonCampaign(Campaign* campaign, const std::vector<Seed>& seeds, const JsonCheck& check) {
  auto run = [&](const std::string& t, const std::string& file) {
    bool accepted = false;
    const std::string problem = check(t, file, &accepted);
    campaign->Check(t, problem, accepted);
  };
  for (size_t k = 0; k < seeds.size(); ++k) {
    const Seed& seed = seeds[k];
    const std::string file = "seeds/mutant " + std::to_string(k) + ".json";
    for (size_t n = 0; n <= seed.text.size(); ++n) {
      run(seed.text.substr(0, n), file);
    }
    for (const Span& sp : seed.spans) {
      for (const std::string& v : seed.SwapsFor(sp)) {
        std::string t = seed.text;
        t.replace(sp.begin, sp.end - sp.begin, v);
        run(t, file);
      }
    }
  }
  Mutator m(kRngSeed);
  for (int i = 0; i < kRandomJsonMutants; ++i) {
    const size_t k = m.Below(seeds.size());
    const std::string file = "seeds/mutant " + std::to_string(k) + ".json";
    std::string t = m.OneIn(2) ? m.SwapValues(seeds[k]) : seeds[k].text;
    const size_t byte_mutations = (t == seeds[k].text) ? 1 + m.Below(4) : m.Below(3);
    for (size_t j = 0; j < byte_mutations; ++j) m.MutateBytes(&t, kJsonAlphabet);
    run(t, file);
  }
}

TEST(ParseMutationTest, CameraJson) {
  std::vector<Seed> seeds;
  for (const std::string& s : CameraSeeds()) seeds.push_back(MakeCameraSeed(s));
  Campaign campaign("camera");
  RunJsonCampaign(&campaign, seeds, [](const std::string& t, const std::string& f, bool* a) {
    return CameraProblem(t, f, a);
  });
  campaign.Report();
}

TEST(ParseMutationTest, SceneJson) {
  std::vector<Seed> seeds;
  for (const std::string& s : SceneSeeds()) seeds.push_back(MakeSeed(s));
  for (const Seed& s : seeds) {
    StatusOr<Scene> scene = ParseScene(s.text, "seed.json");
    ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  }
  Campaign campaign("scene");
  RunJsonCampaign(&campaign, seeds, [](const std::string& t, const std::string& f, bool* a) {
    return SceneProblem(t, f, a);
  });
  campaign.Report();
}

TEST(ParseMutationTest, RayLines) {
  Campaign campaign("ray");
  auto run = [&](const std::string& t) {
    bool accepted = false;
    const std::string problem = RayProblem(t, &accepted);
    campaign.Check(t, problem, accepted);
  };
  for (const char* seed : kRaySeeds) {
    const std::string s = seed;
    ASSERT_TRUE(ParseRayLine(s).ok()) << s;
    for (size_t n = 0; n <= s.size(); ++n) run(s.substr(0, n));
  }
  Mutator m(kRngSeed + 1);
  for (int i = 0; i < kRandomRayMutants; ++i) {
    std::string t = kRaySeeds[m.Below(std::size(kRaySeeds))];
    if (m.OneIn(2)) {
      // Swap one number for an edge-case token.
      std::vector<std::pair<size_t, size_t>> numbers;
      for (size_t p = 0; p < t.size();) {
        if (std::strchr(" \t\r\n", t[p]) != nullptr) {
          ++p;
          continue;
        }
        size_t b = p;
        while (p < t.size() && std::strchr(" \t\r\n", t[p]) == nullptr) ++p;
        numbers.push_back({b, p});
      }
      const auto [b, e] = numbers[m.Below(numbers.size())];
      t.replace(b, e - b, kRayTokenSwaps[m.Below(std::size(kRayTokenSwaps))]);
    }
    for (size_t j = m.Below(3) + (m.OneIn(3) ? 0 : 1); j > 0; --j) m.MutateBytes(&t, kRayAlphabet);
    run(t);
  }
  campaign.Report();
}

// LoadCamera and LoadScene name the path they were given, exactly as
// ParseCamera and ParseScene name their `file`.
TEST(ParseMutationTest, LoadNamesThePath) {
  const std::string dir = ::testing::TempDir();
  Mutator m(kRngSeed + 2);
  const std::vector<std::string> cameras = CameraSeeds(), scenes = SceneSeeds();
  for (int i = 0; i < 40; ++i) {
    const bool camera = i % 2 == 0;
    std::string t = camera ? cameras[m.Below(cameras.size())] : scenes[m.Below(scenes.size())];
    if (i >= 4)  // the first ones load unmodified seeds
      for (size_t j = 1 + m.Below(3); j > 0; --j) m.MutateBytes(&t, kJsonAlphabet);
    const std::string path =
        dir + "vox parse_mutation " + std::to_string(getpid()) + "-" + std::to_string(i) + ".json";
    {
      std::ofstream out(path, std::ios::binary);
      out << t;
      ASSERT_TRUE(out.good()) << path;
    }
    Status loaded, parsed;
    if (camera) {
      StatusOr<Camera> a = LoadCamera(path);
      EXPECT_EQ(CameraProblem(t, path), "") << Quote(t);
      loaded = a.status();
      parsed = ParseCamera(t, path).status();
    } else {
      StatusOr<Scene> a = LoadScene(path);
      EXPECT_EQ(SceneProblem(t, path), "") << Quote(t);
      loaded = a.status();
      parsed = ParseScene(t, path).status();
    }
    EXPECT_EQ(loaded.ToString(), parsed.ToString()) << Quote(t);
    std::remove(path.c_str());
  }
}

// Nesting far deeper than any real file: an error, not a stack overflow.
TEST(ParseMutationTest, DeepNesting) {
  const std::string deep(200000, '[');
  const std::string closed = std::string(100000, '[') + std::string(100000, ']');
  for (const std::string& value : {deep, closed}) {
    const std::string cam = R"({"position":[0,0,1], "look_at":[0,0,0], "fov_deg":40, "width":)" +
                            value + R"(, "height":4})";
    EXPECT_EQ(CameraProblem(cam, "deep.json"), "");
    EXPECT_FALSE(ParseCamera(cam, "deep.json").ok());
    const std::string scene = R"({"lights":)" + value + "}";
    EXPECT_EQ(SceneProblem(scene, "deep.json"), "");
    EXPECT_FALSE(ParseScene(scene, "deep.json").ok());
  }
}

// The bugs the campaigns found, with their exact inputs (each failed before
// its fix).

// render/camera.cpp, Camera::Finalize: scale_y_ = scale_x_ * height / width
// overflowed before the division for an ortho_width near DBL_MAX, and
// PixelRay returned NaN/inf origins.
TEST(ParseMutationTest, HugeOrthoWidthGivesFiniteRays) {
  const char* const inputs[] = {
      R"({"position":[0,0,1], "look_at":[0,0,0], "projection":"orthographic", "ortho_width":1e308, "width":4, "height":4})",
      R"({"projection":"orthographic", "position":[3,-2,5], "look_at":[-1,4,0.5], "up":[0,0,1], "ortho_width":1e308, "width":640, "height":480})"};
  for (const char* t : inputs) EXPECT_EQ(CameraProblem(t, "cam.json"), "") << t;
}

// render/scene.cpp, ParseLight: glm::length() of a direction with a component
// above ~1.3e154 overflowed to inf, and dividing by it left the zero vector:
// a light that lit nothing, and a Scene::ToJson() that ParseScene refused.
TEST(ParseMutationTest, HugeLightDirectionStaysAUnitVector) {
  const char* t = R"({"lights":[{"type":"directional", "direction":[1e200,0,0]}]})";
  EXPECT_EQ(SceneProblem(t, "scene.json"), "") << t;
}

// core/ray_text.cpp, ParseRayLine: the line was read as a C string, so
// anything after a NUL byte was ignored and "1 2 3 4 5 6\0junk" accepted.
TEST(ParseMutationTest, RayLineWithANulByteIsRefused) {
  for (std::string_view t : {"1 2 3 4 5 6\0junk"sv, "1 2 3 4 5 6\0 7"sv})
    EXPECT_EQ(RayProblem(std::string(t)), "") << Quote(t);
}

}  // namespace
}  // namespace vox

#include "render/frame_sequence.h"

#include <cmath>
#include <cstdio>
#include <glm/geometric.hpp>

#include "core/util/file.h"
#include "render/json_fields.h"

namespace vox {
namespace {

bool ParseFrameNumber(const std::string& s, int* out) {
  if (s.empty() || s.size() > 7) return false;
  int v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
  }
  if (v < 1 || v > kMaxFrames) return false;
  *out = v;
  return true;
}

// The conversion of a pattern at path[pos] == '%': its length (%d, %4d,
// %04d: width up to 2 digits), or 0 when it is not one.
size_t ConversionLength(const std::string& path, size_t pos) {
  size_t i = pos + 1;
  size_t digits = 0;
  while (i < path.size() && path[i] >= '0' && path[i] <= '9' && digits < 3) ++i, ++digits;
  const bool zero_flag = digits > 0 && path[pos + 1] == '0';
  if (digits - (zero_flag ? 1 : 0) > 2) return 0;
  if (i < path.size() && path[i] == 'd') return i + 1 - pos;
  return 0;
}

// Rodrigues' rotation of `v` about the unit `axis` by cos/sin of the angle.
glm::dvec3 Rotate(const glm::dvec3& v, const glm::dvec3& axis, double c, double s) {
  return v * c + glm::cross(axis, v) * s + axis * (glm::dot(axis, v) * (1.0 - c));
}

}  // namespace

StatusOr<FrameRange> ParseFrameRange(const std::string& text) {
  const auto error = [&text] {
    return InvalidArgumentError("--frames '" + text +
                                "': expected A-B (frames A to B, 1-based, A <= B) or N, within 1.." +
                                std::to_string(kMaxFrames));
  };
  FrameRange range;
  const size_t dash = text.find('-');
  if (dash == std::string::npos) {
    if (!ParseFrameNumber(text, &range.first)) return error();
    range.last = range.first;
  } else if (!ParseFrameNumber(text.substr(0, dash), &range.first) ||
             !ParseFrameNumber(text.substr(dash + 1), &range.last) || range.last < range.first) {
    return error();
  }
  return range;
}

StatusOr<FrameRange> FramesToRender(int count, const FrameRange* range) {
  if (range == nullptr) return FrameRange{1, count};
  if (range->last > count)
    return InvalidArgumentError(
        "--frames " + std::to_string(range->first) + "-" + std::to_string(range->last) +
        ": the sequence has " + std::to_string(count) + (count == 1 ? " frame" : " frames"));
  return *range;
}

StatusOr<bool> IsFramePattern(const std::string& role, const std::string& path) {
  int conversions = 0;
  bool stray = false;
  for (size_t i = 0; i < path.size(); ++i) {
    if (path[i] != '%') continue;
    if (i + 1 < path.size() && path[i + 1] == '%') {
      ++i;
    } else if (const size_t n = ConversionLength(path, i); n > 0) {
      ++conversions;
      i += n - 1;
    } else {
      stray = true;
    }
  }
  if (conversions == 0) return false;  // a plain name, '%' and all
  if (conversions > 1)
    return InvalidArgumentError(role + " " + path +
                                ": a frame pattern holds one %d (or %04d); write %% for a '%'");
  if (stray)
    return InvalidArgumentError(role + " " + path +
                                ": in a frame pattern only %d, %Nd, %0Nd and %% may follow a '%'");
  return true;
}

std::string ExpandFramePattern(const std::string& path, int frame) {
  bool pattern = false;
  for (size_t i = 0; i < path.size() && !pattern; ++i) {
    if (path[i] != '%') continue;
    if (i + 1 < path.size() && path[i + 1] == '%')
      ++i;
    else
      pattern = ConversionLength(path, i) > 0;
  }
  if (!pattern) return path;  // a plain name, as it is
  std::string out;
  for (size_t i = 0; i < path.size(); ++i) {
    if (path[i] != '%') {
      out += path[i];
    } else if (i + 1 < path.size() && path[i + 1] == '%') {
      out += '%';
      ++i;
    } else if (const size_t n = ConversionLength(path, i); n > 0) {
      char number[128];  // widths up to 99
      snprintf(number, sizeof number, path.substr(i, n).c_str(), frame);
      out += number;
      i += n - 1;
    } else {
      out += '%';
    }
  }
  return out;
}

StatusOr<std::vector<Camera>> ParseCameras(std::string_view json_text, std::string_view file,
                                           const ImageSize* size_if_missing) {
  VOX_ASSIGN_OR_RETURN(const nlohmann::json j, json_fields::Parse(json_text, file, /*allow_array=*/true));
  if (!j.is_array()) {
    VOX_ASSIGN_OR_RETURN(Camera camera, ParseCamera(json_text, file, size_if_missing));
    return std::vector<Camera>{camera};
  }
  if (j.empty())
    return InvalidArgumentError(std::string(file) +
                                ": an empty array; a camera sequence needs at least one camera");
  if (j.size() > size_t(kMaxFrames))
    return InvalidArgumentError(std::string(file) + ": " + std::to_string(j.size()) +
                                " cameras, more than " + std::to_string(kMaxFrames));
  std::vector<Camera> cameras;
  cameras.reserve(j.size());
  for (size_t i = 0; i < j.size(); ++i) {
    const std::string name = std::string(file) + "[" + std::to_string(i) + "]";
    if (!j[i].is_object())
      return InvalidArgumentError(name + ": expected a camera object");
    VOX_ASSIGN_OR_RETURN(Camera camera, ParseCamera(j[i].dump(), name, size_if_missing));
    cameras.push_back(camera);
  }
  return cameras;
}

StatusOr<std::vector<Camera>> LoadCameras(const std::string& path,
                                          const ImageSize* size_if_missing) {
  VOX_ASSIGN_OR_RETURN(std::string text, ReadTextFile(path));
  return ParseCameras(text, path, size_if_missing);
}

glm::dvec3 TurntableAxis(const Camera& camera) {
  glm::dvec3 u;
  if (!json_fields::UnitVector(camera.up, &u)) u = {0, 1, 0};
  if (!camera.camera_to_world) return u;
  int best = 0;
  for (int a = 1; a < 3; ++a)
    if (std::abs(u[a]) > std::abs(u[best])) best = a;
  glm::dvec3 axis(0.0);
  axis[best] = u[best] < 0 ? -1.0 : 1.0;
  return axis;
}

glm::dvec3 TurntablePivot(const Camera& camera, const glm::dvec3& centre) {
  if (!camera.camera_to_world) return camera.look_at;
  const glm::dvec3 f = camera.forward();
  return camera.position + f * glm::dot(centre - camera.position, f);
}

StatusOr<Camera> TurntableCamera(const Camera& base, int count, const glm::dvec3& centre,
                                 int index) {
  if (count < 1 || count > kMaxFrames)
    return InvalidArgumentError("--turntable " + std::to_string(count) + ": must be 1.." +
                                std::to_string(kMaxFrames));
  if (index == 0) return base;
  const glm::dvec3 axis = TurntableAxis(base), pivot = TurntablePivot(base, centre);
  const double angle = 2.0 * M_PI * double(index) / double(count);
  const double c = std::cos(angle), s = std::sin(angle);
  Camera cam = base;
  if (base.camera_to_world) {
    // Turn the pose: its three axes, and its position about the pivot.
    std::array<double, 16> m = *base.camera_to_world;
    for (int col = 0; col < 3; ++col) {
      const glm::dvec3 v = Rotate(glm::dvec3(m[col], m[4 + col], m[8 + col]), axis, c, s);
      for (int row = 0; row < 3; ++row) m[4 * row + col] = v[row];
    }
    const glm::dvec3 p = pivot + Rotate(glm::dvec3(m[3], m[7], m[11]) - pivot, axis, c, s);
    for (int row = 0; row < 3; ++row) m[4 * row + 3] = p[row];
    cam.camera_to_world = m;
  } else {
    cam.position = pivot + Rotate(base.position - pivot, axis, c, s);
    cam.look_at = pivot;
  }
  VOX_RETURN_IF_ERROR(cam.Finalize("--turntable frame " + std::to_string(index + 1)));
  return cam;
}

StatusOr<std::vector<Camera>> TurntableCameras(const Camera& base, int count,
                                               const glm::dvec3& centre) {
  std::vector<Camera> cameras;
  for (int i = 0; i < count || i == 0; ++i) {
    VOX_ASSIGN_OR_RETURN(Camera cam, TurntableCamera(base, count, centre, i));
    cameras.push_back(std::move(cam));
  }
  return cameras;
}

}  // namespace vox

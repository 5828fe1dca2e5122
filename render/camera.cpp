#include "render/camera.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include <Imath/ImathMatrix.h>
#include <glm/geometric.hpp>
#include <limits>
#include <nlohmann/json.hpp>

#include "storage/file.h"
#include "storage/json_fields.h"

namespace vox {
namespace {

// The smallest angle a perspective pixel may span, in radians.
constexpr double kMinPixelAngle = 1e-12;

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

}  // namespace

Status Camera::Finalize(std::string_view source) {
  finalized_ = false;
  auto err = [&](const std::string& field, const std::string& what) {
    return json_fields::FieldError(source, field, what);
  };
  if (!Finite(position)) return err("position", "must be finite");
  if (!Finite(look_at)) return err("look_at", "must be finite");
  if (!Finite(up)) return err("up", "must be finite");
  if (width < 1 || width > kMaxImageSide)
    return err("width", "is " + std::to_string(width) + "; it must be in 1.." +
                            std::to_string(kMaxImageSide));
  if (height < 1 || height > kMaxImageSide)
    return err("height", "is " + std::to_string(height) + "; it must be in 1.." +
                             std::to_string(kMaxImageSide));
  const glm::dvec3 d = look_at - position;
  if (!Finite(d)) return err("look_at", "is too far from position (their difference overflows)");
  glm::dvec3 f, u;
  if (!json_fields::UnitVector(d, &f))
    return err("look_at", "equals position: the view direction is undefined");
  if (!json_fields::UnitVector(up, &u)) return err("up", "is the zero vector");
  glm::dvec3 r = glm::cross(f, u);
  double rlen = glm::length(r);
  if (!(rlen > 1e-9)) return err("up", "is parallel to the view direction (look_at - position)");
  r /= rlen;
  forward_ = f;
  right_ = r;
  true_up_ = glm::cross(r, f);
  if (projection == Projection::kPerspective) {
    if (!std::isfinite(fov_deg) || !(fov_deg > 0) || !(fov_deg < 180))
      return err("fov_deg", "must be in (0, 180) degrees");
    scale_x_ = std::tan(fov_deg * M_PI / 360.0);
    // A pixel must subtend a distinguishable angle: below this, neighbouring
    // pixels' unit directions differ by a few ulps (double resolves about
    // 2.2e-16 of a unit vector) and the image is one ray repeated.
    // (Square pixels: the same angle vertically.)
    const double pixel_angle = 2.0 * scale_x_ / double(width);
    if (!(pixel_angle >= kMinPixelAngle)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", pixel_angle);
      return err("fov_deg", "is too small: a pixel would span " + std::string(buf) +
                                " radians; the minimum is 1e-12 radians per pixel");
    }
  } else {
    if (!std::isfinite(ortho_width) || !(ortho_width > 0))
      return err("ortho_width", "must be positive");
    scale_x_ = 0.5 * ortho_width;
  }
  scale_y_ = scale_x_ * (double(height) / double(width));  // no overflow before the division
  const char* field = projection == Projection::kPerspective ? "fov_deg" : "ortho_width";
  const double tiny = std::numeric_limits<double>::min();
  if (!(scale_x_ / double(width) >= tiny) || !(scale_y_ / double(height) >= tiny))
    return err(field, "is too small: neighbouring pixels would see the same ray");
  for (double x : {0.0, double(width)})
    for (double y : {0.0, double(height)}) {
      const WorldRay ray = PixelRay(x, y);
      if (!Finite(ray.origin) || !Finite(ray.dir))
        return err(field, "is too large: the image's corner rays are not finite");
    }
  finalized_ = true;
  return OkStatus();
}

WorldRay Camera::ScreenRay(double sx, double sy) const {
  WorldRay ray;
  if (projection == Projection::kPerspective) {
    ray.origin = position;
    ray.dir = glm::normalize(forward_ + sx * right_ + sy * true_up_);
  } else {
    ray.origin = position + sx * right_ + sy * true_up_;
    ray.dir = forward_;
  }
  return ray;
}

void Camera::ScreenRays(const double* sx, double sy, int n, WorldRay* out) const {
  int i = 0;
#if defined(__SSE2__)
  if (projection == Projection::kPerspective) {
    // ScreenRay's glm::normalize(v) is v * (1 / sqrt(dot(v, v))): the same
    // correctly rounded operations, on two lanes.
    for (; i + 1 < n; i += 2) {
      const glm::dvec3 v0 = forward_ + sx[i] * right_ + sy * true_up_;
      const glm::dvec3 v1 = forward_ + sx[i + 1] * right_ + sy * true_up_;
      const __m128d inv =
          _mm_div_pd(_mm_set1_pd(1.0), _mm_sqrt_pd(_mm_set_pd(glm::dot(v1, v1), glm::dot(v0, v0))));
      double s[2];
      _mm_storeu_pd(s, inv);
      out[i].origin = position;
      out[i].dir = v0 * s[0];
      out[i + 1].origin = position;
      out[i + 1].dir = v1 * s[1];
    }
  }
#endif
  for (; i < n; ++i) out[i] = ScreenRay(sx[i], sy);
}

std::string Camera::ToJson() const {
  nlohmann::json j;
  j["position"] = {position.x, position.y, position.z};
  j["look_at"] = {look_at.x, look_at.y, look_at.z};
  j["up"] = {up.x, up.y, up.z};
  j["width"] = width;
  j["height"] = height;
  if (projection == Projection::kPerspective) {
    j["projection"] = "perspective";
    j["fov_deg"] = fov_deg;
  } else {
    j["projection"] = "orthographic";
    j["ortho_width"] = ortho_width;
  }
  return j.dump();
}

ExrCameraAttributes StandardCameraAttributes(const Camera& cam) {
  const glm::dvec3 r = cam.right(), u = cam.true_up(), f = cam.forward(), p = cam.position;
  // World -> camera: x right, y up, z along the view (left-handed, as RenderMan).
  Imath::M44d to_camera(r.x, u.x, f.x, 0,  //
                        r.y, u.y, f.y, 0,  //
                        r.z, u.z, f.z, 0,  //
                        -glm::dot(p, r), -glm::dot(p, u), -glm::dot(p, f), 1);
  // Screen half-extents as Camera::PixelRay uses them: pixel x maps to screen
  // (2x/W - 1) sx, pixel y to (1 - 2y/H) sy.
  const bool perspective = cam.projection == Projection::kPerspective;
  const double sx = perspective ? std::tan(cam.fov_deg * M_PI / 360.0) : 0.5 * cam.ortho_width;
  const double sy = sx * (double(cam.height) / double(cam.width));
  // Camera -> NDC ((0,0) top-left, (1,1) bottom-right of the display window).
  // Perspective: X = x/(2 sx) + z/2, Y = -y/(2 sy) + z/2, W = z (Z = 1, so
  // the matrix is invertible and z/w is 1/depth); orthographic: W = 1 and
  // z stays the depth.
  const Imath::M44d to_ndc =
      perspective ? Imath::M44d(0.5 / sx, 0, 0, 0,   //
                                0, -0.5 / sy, 0, 0,  //
                                0.5, 0.5, 0, 1,      //
                                0, 0, 1, 0)
                  : Imath::M44d(0.5 / sx, 0, 0, 0,   //
                                0, -0.5 / sy, 0, 0,  //
                                0, 0, 1, 0,          //
                                0.5, 0.5, 0, 1);
  const Imath::M44d world_to_ndc = to_camera * to_ndc;
  // Single precision, row by row, as the header keeps them.
  const auto rows = [](const Imath::M44d& m) {
    const Imath::M44f single(m);
    std::array<float, 16> out;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) out[size_t(4 * i + j)] = single[i][j];
    return out;
  };
  ExrCameraAttributes a;
  a.world_to_camera = rows(to_camera);
  a.world_to_ndc = rows(world_to_ndc);
  a.screen_window_width = float(2.0 * sx);
  return a;
}

StatusOr<Camera> ParseCamera(std::string_view json_text, std::string_view file) {
  namespace jf = json_fields;
  VOX_ASSIGN_OR_RETURN(nlohmann::json j, jf::Parse(json_text, file));
  VOX_RETURN_IF_ERROR(jf::CheckKnownKeys(
      j, {"position", "look_at", "up", "fov_deg", "width", "height", "projection", "ortho_width"},
      file, ""));
  Camera cam;
  std::string projection = "perspective";
  VOX_RETURN_IF_ERROR(jf::GetString(j, "projection", file, "", false, &projection));
  if (projection == "perspective") {
    cam.projection = Projection::kPerspective;
  } else if (projection == "orthographic") {
    cam.projection = Projection::kOrthographic;
  } else {
    return jf::FieldError(file, "projection",
                          "is '" + projection + "'; it must be 'perspective' or 'orthographic'");
  }
  VOX_RETURN_IF_ERROR(jf::GetVec3(j, "position", file, "", true, &cam.position));
  VOX_RETURN_IF_ERROR(jf::GetVec3(j, "look_at", file, "", true, &cam.look_at));
  VOX_RETURN_IF_ERROR(jf::GetVec3(j, "up", file, "", false, &cam.up));
  VOX_RETURN_IF_ERROR(jf::GetInt(j, "width", file, "", true, 1, kMaxImageSide, &cam.width));
  VOX_RETURN_IF_ERROR(jf::GetInt(j, "height", file, "", true, 1, kMaxImageSide, &cam.height));
  if (cam.projection == Projection::kPerspective) {
    VOX_RETURN_IF_ERROR(jf::GetNumber(j, "fov_deg", file, "", true, &cam.fov_deg));
    if (j.contains("ortho_width"))
      return jf::FieldError(file, "ortho_width", "only applies to an orthographic projection");
  } else {
    VOX_RETURN_IF_ERROR(jf::GetNumber(j, "ortho_width", file, "", true, &cam.ortho_width));
    if (j.contains("fov_deg"))
      return jf::FieldError(file, "fov_deg", "only applies to a perspective projection");
  }
  VOX_RETURN_IF_ERROR(cam.Finalize(file));
  return cam;
}

StatusOr<Camera> LoadCamera(const std::string& path) {
  VOX_ASSIGN_OR_RETURN(std::string text, ReadTextFile(path));
  return ParseCamera(text, path);
}

Camera DefaultCamera(const glm::dvec3& lo, const glm::dvec3& hi, int width, int height) {
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.projection = Projection::kPerspective;
  cam.fov_deg = 40.0;
  glm::dvec3 centre = 0.5 * (lo + hi);
  double radius = 0.5 * glm::length(hi - lo);
  if (!(radius > 0)) radius = 1.0;
  // Fit the bounding sphere in the narrower field of view.
  double half_h = cam.fov_deg * M_PI / 360.0;
  double half_v = std::atan(std::tan(half_h) * double(height) / double(width));
  double half = std::min(half_h, half_v);
  double dist = radius / std::sin(half) * 1.02;
  glm::dvec3 view_dir = glm::normalize(glm::dvec3(0.55, 0.45, 0.7));
  cam.position = centre + view_dir * dist;
  cam.look_at = centre;
  cam.up = {0.0, 1.0, 0.0};
  Status s = cam.Finalize("default camera");
  (void)s;  // cannot fail: finite box, up not parallel to view_dir
  return cam;
}

Status CheckCameraDistance(const Camera& cam, const glm::dvec3& lo, const glm::dvec3& hi) {
  // Per-axis (Chebyshev) distances: no overflow for any finite position.
  double size = 0, dist = 0;
  for (int a = 0; a < 3; ++a) {
    size = std::max(size, hi[a] - lo[a]);
    const double p = cam.position[a];
    dist = std::max(dist, p < lo[a] ? lo[a] - p : p > hi[a] ? p - hi[a] : 0.0);
  }
  size = std::max(size, 1e-300);
  if (!(dist <= kMaxCameraDistanceInBoxes * size)) {
    char m[256];
    snprintf(m, sizeof m,
             "camera position is %.6g away from the volume, %.3g times its size; vox-render "
             "supports cameras within %.0f volume sizes (precision of hit points)",
             dist, dist / size, kMaxCameraDistanceInBoxes);
    return InvalidArgumentError(m);
  }
  return OkStatus();
}

}  // namespace vox

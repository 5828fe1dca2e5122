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
#include <vector>

#include "core/util/file.h"
#include "render/json_fields.h"

namespace vox {
namespace {

// The smallest angle a perspective pixel may span, in radians.
constexpr double kMinPixelAngle = 1e-12;

bool Finite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// cam.json's camera_to_world: 16 numbers, or 4 rows of 4, row-major.
StatusOr<std::array<double, 16>> ReadMatrix(const nlohmann::json& v, std::string_view file) {
  namespace jf = json_fields;
  const char* what = "must be 16 numbers or 4 rows of 4 numbers (row-major)";
  std::vector<const nlohmann::json*> items;
  if (v.is_array() && v.size() == 16) {
    for (const auto& x : v) items.push_back(&x);
  } else if (v.is_array() && v.size() == 4) {
    for (const auto& row : v) {
      if (!row.is_array() || row.size() != 4) return jf::FieldError(file, "camera_to_world", what);
      for (const auto& x : row) items.push_back(&x);
    }
  } else {
    return jf::FieldError(file, "camera_to_world", what);
  }
  std::array<double, 16> m{};
  for (size_t i = 0; i < 16; ++i)
    VOX_RETURN_IF_ERROR(jf::ReadNumber(*items[i], file, "camera_to_world", &m[i]));
  return m;
}

// A perspective camera's lens: fov_deg, or focal_length_mm with the sensor's
// (film back's) width, sensor_width_mm or aperture_mm, spanning the image's
// width: fov = 2 atan(sensor / (2 focal)).
Status ReadLens(const nlohmann::json& j, std::string_view file, Camera* cam) {
  namespace jf = json_fields;
  if (!j.contains("focal_length_mm")) {
    for (const char* k : {"sensor_width_mm", "aperture_mm"})
      if (j.contains(k)) return jf::FieldError(file, k, "needs focal_length_mm");
    return jf::GetNumber(j, "fov_deg", file, "", true, &cam->fov_deg);
  }
  for (const char* k : {"fov_deg", "fov_axis"})
    if (j.contains(k))
      return jf::FieldError(file, k,
                            "and focal_length_mm both give the field of view; give one (the "
                            "sensor width spans the image's width)");
  const bool sensor = j.contains("sensor_width_mm"), aperture = j.contains("aperture_mm");
  if (sensor == aperture)
    return jf::FieldError(file, "focal_length_mm",
                          sensor ? "takes sensor_width_mm or aperture_mm (the same width); give one"
                                 : "needs the sensor's width: sensor_width_mm (or aperture_mm, "
                                   "the horizontal aperture), e.g. 36");
  double focal = 0, width = 0;
  const char* width_key = sensor ? "sensor_width_mm" : "aperture_mm";
  VOX_RETURN_IF_ERROR(jf::GetNumber(j, "focal_length_mm", file, "", true, &focal));
  VOX_RETURN_IF_ERROR(jf::GetNumber(j, width_key, file, "", true, &width));
  if (!(focal > 0) || !std::isfinite(focal))
    return jf::FieldError(file, "focal_length_mm", "must be a positive number of millimetres");
  if (!(width > 0) || !std::isfinite(width))
    return jf::FieldError(file, width_key, "must be a positive number of millimetres");
  cam->fov_axis = FovAxis::kX;
  cam->fov_deg = 2.0 * std::atan(width / (2.0 * focal)) * 180.0 / M_PI;
  return OkStatus();
}

}  // namespace

Status Camera::ComputeFrame(std::string_view source) {
  auto err = [&](const std::string& field, const std::string& what) {
    return json_fields::FieldError(source, field, what);
  };
  if (camera_to_world) {
    const std::array<double, 16>& m = *camera_to_world;
    for (double v : m)
      if (!std::isfinite(v)) return err("camera_to_world", "must be finite");
    if (m[12] != 0 || m[13] != 0 || m[14] != 0 || m[15] != 1) {
      if (m[3] == 0 && m[7] == 0 && m[11] == 0 && m[15] == 1)
        return err("camera_to_world",
                   "must have the last row 0 0 0 1, but its last column is 0 0 0 1: it looks "
                   "transposed (a matrix for row vectors, as Houdini's): transpose it, or set "
                   "\"row_major\": true");
      return err("camera_to_world", "must have the last row 0 0 0 1");
    }
    glm::dvec3 axis[3];
    for (int c = 0; c < 3; ++c) {
      axis[c] = glm::dvec3(m[c], m[4 + c], m[8 + c]);
      const double len = glm::length(axis[c]);
      if (!(len > 1e-12)) return err("camera_to_world", "has a zero axis");
      if (!std::isfinite(len))
        return err("camera_to_world", "has an axis too long to normalise (its length overflows)");
      // Unit columns are taken as they are (bit for bit the look_at frame
      // they were written from); scaled ones are normalised.
      if (std::abs(len - 1.0) > 1e-12) axis[c] /= len;
    }
    const double tol = 1e-6;
    if (std::abs(glm::dot(axis[0], axis[1])) > tol || std::abs(glm::dot(axis[0], axis[2])) > tol ||
        std::abs(glm::dot(axis[1], axis[2])) > tol)
      return err("camera_to_world", "is not a rotation: its axes are not orthogonal (shear)");
    if (!(glm::dot(glm::cross(axis[0], axis[1]), axis[2]) > 0))
      return err("camera_to_world", "is not a rotation: it mirrors (negative determinant)");
    right_ = axis[0];
    true_up_ = axis[1];
    forward_ = -axis[2];  // the camera looks along its local -Z
    position = glm::dvec3(m[3], m[7], m[11]);
    look_at = position + forward_;
    up = true_up_;
    return OkStatus();
  }
  if (!Finite(position)) return err("position", "must be finite");
  if (!Finite(look_at)) return err("look_at", "must be finite");
  if (!Finite(up)) return err("up", "must be finite");
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
  return OkStatus();
}

Status Camera::Finalize(std::string_view source) {
  finalized_ = false;
  auto err = [&](const std::string& field, const std::string& what) {
    return json_fields::FieldError(source, field, what);
  };
  VOX_RETURN_IF_ERROR(ComputeFrame(source));
  if (width < 1 || width > kMaxImageSide)
    return err("width", "is " + std::to_string(width) + "; it must be in 1.." +
                            std::to_string(kMaxImageSide));
  if (height < 1 || height > kMaxImageSide)
    return err("height", "is " + std::to_string(height) + "; it must be in 1.." +
                             std::to_string(kMaxImageSide));
  const double aspect = double(height) / double(width);
  // fov_deg spans y: the vertical axis, or the smaller side of a landscape image.
  const bool fov_y = projection == Projection::kPerspective &&
                     (fov_axis == FovAxis::kY || (fov_axis == FovAxis::kSmaller && height < width));
  if (projection == Projection::kPerspective) {
    if (!std::isfinite(fov_deg) || !(fov_deg > 0) || !(fov_deg < 180))
      return err("fov_deg", "must be in (0, 180) degrees");
    scale_x_ = std::tan(fov_deg * M_PI / 360.0);
    if (fov_y) {
      scale_y_ = scale_x_;
      scale_x_ = scale_y_ * (double(width) / double(height));
    }
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
  if (!fov_y) scale_y_ = scale_x_ * aspect;  // no overflow before the division
  const char* field = projection == Projection::kPerspective ? "fov_deg" : "ortho_width";
  const double tiny = std::numeric_limits<double>::min();
  if (!std::isfinite(scale_x_) || !(scale_x_ / double(width) >= tiny) ||
      !(scale_y_ / double(height) >= tiny))
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

double Camera::HorizontalFovDeg() const {
  if (projection != Projection::kPerspective || fov_axis == FovAxis::kX ||
      (fov_axis == FovAxis::kSmaller && width <= height))
    return fov_deg;
  return std::atan(std::tan(fov_deg * M_PI / 360.0) * double(width) / double(height)) * 360.0 /
         M_PI;
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
  if (camera_to_world) {
    j["camera_to_world"] = *camera_to_world;
  } else {
    j["position"] = {position.x, position.y, position.z};
    j["look_at"] = {look_at.x, look_at.y, look_at.z};
    j["up"] = {up.x, up.y, up.z};
  }
  j["width"] = width;
  j["height"] = height;
  if (projection == Projection::kPerspective) {
    j["projection"] = "perspective";
    j["fov_deg"] = fov_deg;
    if (fov_axis != FovAxis::kX) j["fov_axis"] = fov_axis == FovAxis::kY ? "y" : "smaller";
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
  const double sx = cam.scale_x(), sy = cam.scale_y();
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

StatusOr<Camera> ParseCamera(std::string_view json_text, std::string_view file,
                             const ImageSize* size_if_missing) {
  namespace jf = json_fields;
  VOX_ASSIGN_OR_RETURN(nlohmann::json j, jf::Parse(json_text, file));
  VOX_RETURN_IF_ERROR(
      jf::CheckKnownKeys(j,
                         {"position", "look_at", "up", "camera_to_world", "row_major", "fov_deg",
                          "fov_axis", "focal_length_mm", "sensor_width_mm", "aperture_mm", "width",
                          "height", "projection", "ortho_width"},
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
  if (auto it = j.find("camera_to_world"); it != j.end()) {
    for (const char* k : {"position", "look_at", "up"})
      if (j.contains(k))
        return jf::FieldError(file, k, "and camera_to_world both place the camera; give one");
    VOX_ASSIGN_OR_RETURN(cam.camera_to_world, ReadMatrix(*it, file));
    bool row_major = false;
    VOX_RETURN_IF_ERROR(jf::GetBool(j, "row_major", file, "", &row_major));
    if (row_major) {
      // For row vectors (p' = p M): the translation is the last row.
      std::array<double, 16>& m = *cam.camera_to_world;
      if (m[3] != 0 || m[7] != 0 || m[11] != 0 || m[15] != 1)
        return jf::FieldError(file, "camera_to_world",
                              "must have the last column 0 0 0 1 with \"row_major\": true (a "
                              "matrix for row vectors); for column vectors, leave row_major out");
      for (int r = 0; r < 4; ++r)
        for (int c = r + 1; c < 4; ++c) std::swap(m[size_t(4 * r + c)], m[size_t(4 * c + r)]);
    }
  } else {
    if (j.contains("row_major"))
      return jf::FieldError(file, "row_major", "only applies to camera_to_world");
    VOX_RETURN_IF_ERROR(jf::GetVec3(j, "position", file, "", true, &cam.position));
    VOX_RETURN_IF_ERROR(jf::GetVec3(j, "look_at", file, "", true, &cam.look_at));
    VOX_RETURN_IF_ERROR(jf::GetVec3(j, "up", file, "", false, &cam.up));
  }
  std::string axis = "x";
  VOX_RETURN_IF_ERROR(jf::GetString(j, "fov_axis", file, "", false, &axis));
  if (axis == "y") {
    cam.fov_axis = FovAxis::kY;
  } else if (axis == "smaller") {
    cam.fov_axis = FovAxis::kSmaller;
  } else if (axis != "x") {
    return jf::FieldError(file, "fov_axis", "is '" + axis + "'; it must be 'x', 'y' or 'smaller'");
  }
  for (const char* k : {"width", "height"})
    if (!j.contains(k) && size_if_missing == nullptr)
      return jf::FieldError(file, k,
                            "is missing (give width and height, or vox-render --size WxH)");
  if (size_if_missing != nullptr) {
    cam.width = size_if_missing->width;
    cam.height = size_if_missing->height;
  }
  VOX_RETURN_IF_ERROR(jf::GetInt(j, "width", file, "", false, 1, kMaxImageSide, &cam.width));
  VOX_RETURN_IF_ERROR(jf::GetInt(j, "height", file, "", false, 1, kMaxImageSide, &cam.height));
  if (cam.projection == Projection::kPerspective) {
    VOX_RETURN_IF_ERROR(ReadLens(j, file, &cam));
    if (j.contains("ortho_width"))
      return jf::FieldError(file, "ortho_width", "only applies to an orthographic projection");
  } else {
    VOX_RETURN_IF_ERROR(jf::GetNumber(j, "ortho_width", file, "", true, &cam.ortho_width));
    for (const char* k :
         {"fov_deg", "fov_axis", "focal_length_mm", "sensor_width_mm", "aperture_mm"})
      if (j.contains(k))
        return jf::FieldError(file, k, "only applies to a perspective projection");
  }
  VOX_RETURN_IF_ERROR(cam.Finalize(file));
  return cam;
}

StatusOr<Camera> LoadCamera(const std::string& path, const ImageSize* size_if_missing) {
  VOX_ASSIGN_OR_RETURN(std::string text, ReadTextFile(path));
  return ParseCamera(text, path, size_if_missing);
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

StatusOr<Camera> OrbitCamera(const Camera& base, const glm::dvec3& lo, const glm::dvec3& hi,
                             double azimuth_deg, double elevation_deg) {
  if (!std::isfinite(azimuth_deg))
    return InvalidArgumentError("--view: the azimuth must be a finite number of degrees");
  if (!(std::abs(elevation_deg) < 90))
    return InvalidArgumentError("--view: the elevation must be within (-90, 90) degrees");
  if (!Finite(lo) || !Finite(hi))
    return InvalidArgumentError("--view: the volume's world box is not finite");
  Camera c = base;
  c.camera_to_world.reset();
  // The axis to turn about: `up`; for a camera_to_world camera, the world
  // axis nearest its own up (its y axis may be tilted).
  glm::dvec3 u;
  if (!json_fields::UnitVector(base.up, &u)) u = {0, 1, 0};
  if (base.camera_to_world) {
    int best = 0;
    for (int a = 1; a < 3; ++a)
      if (std::abs(u[a]) > std::abs(u[best])) best = a;
    glm::dvec3 axis(0.0);
    axis[best] = u[best] < 0 ? -1.0 : 1.0;
    u = axis;
  }
  // The front: +Z, or -Y when up is (nearly) Z, made perpendicular to up.
  const glm::dvec3 front0 = std::abs(u.z) < 0.9 ? glm::dvec3(0, 0, 1) : glm::dvec3(0, -1, 0);
  const glm::dvec3 front = glm::normalize(front0 - glm::dot(front0, u) * u);
  const glm::dvec3 side = glm::cross(u, front);
  const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
  // w: from the box's centre towards the camera.
  const glm::dvec3 w = glm::normalize(std::cos(el) * (std::cos(az) * front + std::sin(az) * side) +
                                      std::sin(el) * u);
  const glm::dvec3 centre = 0.5 * (lo + hi);
  c.up = u;
  c.look_at = centre;
  c.position = centre + w;
  VOX_RETURN_IF_ERROR(c.Finalize("--view"));  // the frame and screen extents at this direction
  const glm::dvec3 r = c.right(), v = c.true_up();
  const double margin = 0.98;  // the box's extreme corner 2% inside the frame
  double size = 0;
  for (int a = 0; a < 3; ++a) size = std::max(size, hi[a] - lo[a]);
  if (!(size > 0)) size = 1.0;
  double dist = 0, ahead = -std::numeric_limits<double>::infinity(), width = 0;
  for (int k = 0; k < 8; ++k) {
    const glm::dvec3 q =
        glm::dvec3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z) - centre;
    const double x = std::abs(glm::dot(q, r)), y = std::abs(glm::dot(q, v)), z = glm::dot(q, w);
    // Perspective: the corner fits where depth (dist - z) >= x / sx and y / sy.
    dist = std::max(dist, std::max(x / (c.scale_x() * margin), y / (c.scale_y() * margin)) + z);
    ahead = std::max(ahead, z);
    width = std::max({width, 2 * x / margin, 2 * y * double(c.width) / double(c.height) / margin});
  }
  if (c.projection == Projection::kOrthographic) {
    c.ortho_width = width > 0 ? width : size;
    dist = ahead + size;  // in front of every corner
  }
  dist = std::max(dist, ahead + 1e-3 * size);
  c.position = centre + dist * w;
  VOX_RETURN_IF_ERROR(c.Finalize("--view"));
  return c;
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

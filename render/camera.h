// vox::Camera: the pinhole (perspective) and orthographic cameras of
// vox-render, read from cam.json, and the primary rays through pixel centres.
// docs/usage.md describes cam.json for users.
//
// cam.json, in the world space of the source VDB:
//   {"position":[x,y,z], "look_at":[x,y,z], "up":[0,1,0], "fov_deg":F,
//    "width":W, "height":H, "projection":"perspective"}
// or "projection":"orthographic" with "ortho_width":S (world units across the
// image). fov_deg is the horizontal field of view, as vdb_render's -fov,
// unless "fov_axis" says otherwise: "x" (default), "y" (vertical) or
// "smaller" (the image's smaller side), as Mitsuba's fov_axis; perspective
// only. The image plane follows vdb_render's camera (pixel (i, j) maps to
// screen ((2(i + 0.5)/W - 1) sx, (1 - 2(j + 0.5)/H) sy), sx / sy = W / H),
// so row 0 is the top row.
// Instead of fov_deg, "focal_length_mm" with "sensor_width_mm" (or
// "aperture_mm", the horizontal aperture) gives the lens as DCCs do: the
// sensor spans the image's width, fov_deg = 2 atan(sensor / (2 focal)).
// Instead of position, look_at and up, "camera_to_world" may give the
// camera's pose as a 4x4 row-major matrix (16 numbers, or 4 rows of 4) acting
// on column vectors, as Blender's matrix_world and Mitsuba's to_world (with
// "row_major": true, a matrix acting on row vectors, as Houdini's, with the
// position in its last row: it is transposed first): its
// columns are the camera's x (right), y (up) and z axes and its position in
// world space; the camera looks along its local -Z (Blender, OpenGL,
// Mitsuba). The rotation must be orthonormal (columns are normalised; no
// shear, no mirror) and the last row 0 0 0 1. The same camera given both
// ways renders the same image, bit for bit.
// "up" defaults to [0,1,0] and "projection" to "perspective"; the other
// fields are required (width and height may come from vox-render --size). Unknown fields are
// refused (they are usually typos).
//
// Thread safety: a Camera is an immutable value once Finalize()d; PixelRay is
// const and thread-safe.
#ifndef VOX_RENDER_CAMERA_H_
#define VOX_RENDER_CAMERA_H_

#include <array>
#include <optional>
#include <glm/vec3.hpp>
#include <string>
#include <string_view>

#include "core/util/status.h"
#include "render/limits.h"

namespace vox {

enum class Projection { kPerspective, kOrthographic };
// Which side of the image fov_deg spans (cam.json's fov_axis).
enum class FovAxis { kX, kY, kSmaller };

// A ray in world space; `dir` has unit length.
struct WorldRay {
  glm::dvec3 origin{0.0};
  glm::dvec3 dir{0.0, 0.0, -1.0};
};

class Camera {
 public:
  glm::dvec3 position{0.0, 0.0, 1.0};
  glm::dvec3 look_at{0.0};
  glm::dvec3 up{0.0, 1.0, 0.0};
  double fov_deg = 40.0;
  double ortho_width = 1.0;
  int width = 0, height = 0;
  Projection projection = Projection::kPerspective;
  FovAxis fov_axis = FovAxis::kX;
  // cam.json's camera_to_world (row-major, column vectors): when set,
  // Finalize takes the frame and position from it, and sets position,
  // look_at (one unit ahead) and up from it.
  std::optional<std::array<double, 16>> camera_to_world;

  // Checks the fields (finite, positive size, fov in (0, 180), up not
  // parallel to the view direction) and computes the camera frame. `source`
  // names where the camera came from, for the messages. Call it again after
  // changing a field.
  Status Finalize(std::string_view source = "camera");
  // Whether Finalize() has succeeded (the renderer refuses a camera without it).
  bool finalized() const { return finalized_; }

  // The ray through image position (x, y), in pixels from the top-left
  // corner: pixel (i, j)'s centre is (i + 0.5, j + 0.5). REQUIRES: Finalize().
  WorldRay PixelRay(double x, double y) const { return ScreenRay(ScreenX(x), ScreenY(y)); }
  // PixelRay in two parts, for callers that reuse a row's or a column's
  // screen coordinate (the same arithmetic, so the same bits): the screen
  // coordinates of image position x and y, and the ray through them.
  double ScreenX(double x) const { return (2.0 * x / double(width) - 1.0) * scale_x_; }
  double ScreenY(double y) const { return (1.0 - 2.0 * y / double(height)) * scale_y_; }
  WorldRay ScreenRay(double sx, double sy) const;
  // ScreenRay(sx[i], sy) for i < n into out[i], bit for bit, with the
  // square roots and divisions of two rays at a time.
  void ScreenRays(const double* sx, double sy, int n, WorldRay* out) const;

  const glm::dvec3& forward() const { return forward_; }
  const glm::dvec3& right() const { return right_; }
  const glm::dvec3& true_up() const { return true_up_; }
  // The screen half-extents: pixel x maps to screen (2x/W - 1) scale_x(),
  // pixel y to (1 - 2y/H) scale_y(); tan(fov/2) or ortho_width / 2 across x.
  double scale_x() const { return scale_x_; }
  double scale_y() const { return scale_y_; }
  // The horizontal field of view in degrees: fov_deg when fov_axis spans x.
  double HorizontalFovDeg() const;

  // The camera as cam.json text (one line), for EXR headers, logs and
  // --save-cam: camera_to_world when it was given, else position, look_at
  // and up; parsed back, it gives the same rays bit for bit.
  std::string ToJson() const;

 private:
  // Finalize's frame: from camera_to_world, or from position, look_at, up.
  Status ComputeFrame(std::string_view source);

  glm::dvec3 forward_{0.0, 0.0, -1.0}, right_{1.0, 0.0, 0.0}, true_up_{0.0, 1.0, 0.0};
  double scale_x_ = 1.0, scale_y_ = 1.0;  // screen half-extent (tan(fov/2) or ortho_width / 2)
  bool finalized_ = false;
};

// OpenEXR's standard camera attributes (ImfStandardAttributes.h) of a
// camera, as render/exr.h describes them: matrices act on row vectors
// (p' = p * M) and are stored row by row, in single precision as the header
// keeps them; the screen window is centred on (0, 0).
struct ExrCameraAttributes {
  std::array<float, 16> world_to_camera{};  // x right, y up, z along the view
  std::array<float, 16> world_to_ndc{};     // (0, 0) top-left, (1, 1) bottom-right
  float screen_window_width = 0.0f;         // at z = 1 (perspective), or ortho_width
};
// REQUIRES: cam.Finalize().
ExrCameraAttributes StandardCameraAttributes(const Camera& cam);

// The image size for a cam.json without width and height (vox-render
// --size): each one missing is taken from it.
struct ImageSize {
  int width = 0, height = 0;
};

// Parses cam.json text; `file` names it in every error ("cam.json: field
// 'width' must be a positive integer"). Without `size_if_missing`, width and
// height are required.
StatusOr<Camera> ParseCamera(std::string_view json_text, std::string_view file,
                             const ImageSize* size_if_missing = nullptr);
// Reads and parses a cam.json file.
StatusOr<Camera> LoadCamera(const std::string& path, const ImageSize* size_if_missing = nullptr);

// How far a camera may be from the volume it renders, in sizes of the
// volume's world box: hit points are computed from the camera position, and
// farther away they lose their voxel in double precision.
inline constexpr double kMaxCameraDistanceInBoxes = 65536.0;

// OkStatus when `cam`'s position is within kMaxCameraDistanceInBoxes box
// sizes of the world box [lo, hi] (per axis: the largest
// distance over its largest side); else an error naming
// the distance and the limit.
Status CheckCameraDistance(const Camera& cam, const glm::dvec3& lo, const glm::dvec3& hi);

// A perspective camera that frames the world box [lo, hi] from a three-quarter
// view above it, with the whole box in the image.
Camera DefaultCamera(const glm::dvec3& lo, const glm::dvec3& hi, int width, int height);

// `base` (its projection, field of view, fov_axis, size and up) moved to look
// at the centre of the world box [lo, hi] from azimuth and elevation in
// degrees (vox-render --view), at the distance where the box's corners just
// fit the image (2% margin; orthographic: ortho_width fits them). Azimuth
// turns about `up` from the front: +Z for a Y-up camera (+X at 90 degrees),
// -Y for a Z-up one (+X at 90); elevation raises the camera towards `up`
// and must lie in (-90, 90). A camera_to_world camera turns about the world
// axis nearest its own up.
StatusOr<Camera> OrbitCamera(const Camera& base, const glm::dvec3& lo, const glm::dvec3& hi,
                             double azimuth_deg, double elevation_deg);

}  // namespace vox

#endif  // VOX_RENDER_CAMERA_H_

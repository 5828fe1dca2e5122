// vox::Camera: the pinhole (perspective) and orthographic cameras of
// vox-render, read from cam.json, and the primary rays through pixel centres.
//
// cam.json, in the world space of the source VDB:
//   {"position":[x,y,z], "look_at":[x,y,z], "up":[0,1,0], "fov_deg":F,
//    "width":W, "height":H, "projection":"perspective"}
// or "projection":"orthographic" with "ortho_width":S (world units across the
// image). fov_deg is the horizontal field of view, as vdb_render's -fov; the
// image plane follows vdb_render's camera (pixel (i, j) maps to screen
// ((2(i + 0.5)/W - 1) s, (1 - 2(j + 0.5)/H) s H/W)), so row 0 is the top row.
// "up" defaults to [0,1,0] and "projection" to "perspective"; the other
// fields are required. Unknown fields are refused (they are usually typos).
//
// Thread safety: a Camera is an immutable value once Finalize()d; PixelRay is
// const and thread-safe.
#ifndef VOX_RENDER_CAMERA_H_
#define VOX_RENDER_CAMERA_H_

#include <array>
#include <glm/vec3.hpp>
#include <string>
#include <string_view>

#include "core/status.h"
#include "render/limits.h"

namespace vox {

enum class Projection { kPerspective, kOrthographic };

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

  // The camera as cam.json text (one line), for EXR headers and logs.
  std::string ToJson() const;

 private:
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

// Parses cam.json text; `file` names it in every error ("cam.json: field
// 'width' must be a positive integer").
StatusOr<Camera> ParseCamera(std::string_view json_text, std::string_view file);
// Reads and parses a cam.json file.
StatusOr<Camera> LoadCamera(const std::string& path);

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

}  // namespace vox

#endif  // VOX_RENDER_CAMERA_H_

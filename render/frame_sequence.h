// Frame sequences of vox-render (docs/usage.md, "Frame sequences"): the
// cameras of a sequence (a cam.json array, or a turntable around one
// camera's look-at point), the frames a run renders (--frames A-B) and the
// printf frame patterns of its outputs (-o out.%04d.exr).
//
// Frames are numbered from 1. A sequence of more than one frame needs a
// pattern for every per-frame output, so that no two frames (and no two
// array tasks of a Slurm job) write one file.
//
// Thread safety: pure functions.
#ifndef VOX_RENDER_FRAME_SEQUENCE_H_
#define VOX_RENDER_FRAME_SEQUENCE_H_

#include <glm/vec3.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/path_identity.h"
#include "core/util/status.h"
#include "render/camera.h"

namespace vox {

// The most frames a sequence may have (a --cam array's cameras, --turntable N).
inline constexpr int kMaxFrames = 1000000;

// --frames: the first and last frame a run renders, 1-based and inclusive.
struct FrameRange {
  int first = 1;
  int last = 1;
};

// "A-B" (A <= B) or "N" (the frame N alone); frames in 1..kMaxFrames.
// InvalidArgument naming `text` otherwise.
StatusOr<FrameRange> ParseFrameRange(const std::string& text);

// The frames to render of a sequence of `count` frames: `range` when given
// (InvalidArgument when it ends after the sequence), else all of them.
StatusOr<FrameRange> FramesToRender(int count, const FrameRange* range);

// Whether `path` is a frame pattern: it holds one printf conversion %d, %Nd
// or %0Nd (N: 1..2 digits), where `%%` stands for a `%`. A path without
// any %d is a plain name, taken as it is (a `%` in it included).
// InvalidArgument, naming `role` ("-o"), for two conversions or a `%` that
// is neither %% nor the conversion in a pattern.
StatusOr<bool> IsFramePattern(const std::string& role, const std::string& path);

// The pattern with `frame` in place of its conversion, %% turned into %;
// a plain name as it is. REQUIRES: IsFramePattern(path) succeeded.
std::string ExpandFramePattern(const std::string& path, int frame);

// The one frame whose expansion of `pattern` is `path` (ExpandFramePattern
// gives `path` back), or 0 when none in 1..kMaxFrames. A plain name matches
// itself with every frame: 0 unless equal, else -1.
int MatchFramePattern(const std::string& pattern, const std::string& path);

// The outputs of the frames `range` of a run (each a frame pattern or a
// plain name, checked by IsFramePattern) checked against each other and
// against the existing `inputs`, in time linear in their number, not in the
// frames': InvalidArgument, naming the frame and both paths, when two of a
// frame's or of two frames' outputs are one file, or an output is an input.
// Paths are compared as the same name in the same directory (by identity,
// as core/util/path_identity.h does), where the frame number is in the name;
// a pattern with its number in a directory is compared as text. Each
// frame's outputs are compared by identity again when it comes
// (CheckDistinctPaths), for links among existing files.
Status CheckFrameOutputs(const std::vector<NamedPath>& inputs,
                         const std::vector<NamedPath>& outputs, FrameRange range);

// The cameras of cam.json text: one camera object, or a non-empty array of
// them (a sequence). Errors name `file` and, in an array, the element
// ("cams.json[2]: field 'width' ..."). `size_if_missing`: as ParseCamera's.
StatusOr<std::vector<Camera>> ParseCameras(std::string_view json_text, std::string_view file,
                                           const ImageSize* size_if_missing = nullptr);

// Reads and parses a cam.json file of one camera or an array of them.
StatusOr<std::vector<Camera>> LoadCameras(const std::string& path,
                                          const ImageSize* size_if_missing = nullptr);

// The axis a turntable (and --view) turns about: `camera`'s up, or for a
// camera_to_world camera the world axis nearest its own up. Unit length.
glm::dvec3 TurntableAxis(const Camera& camera);

// The point a turntable turns about: the look-at point, or for a
// camera_to_world camera the point of its view axis nearest `centre` (the
// volume's world-box centre; its look_at is only one unit ahead).
glm::dvec3 TurntablePivot(const Camera& camera, const glm::dvec3& centre);

// `count` cameras: `base` turned about TurntableAxis through
// TurntablePivot by 360 i / count degrees, i = 0 .. count - 1 (frame i + 1;
// the first is `base` itself): the same distance to the pivot, the same
// elevation above the plane across the axis, azimuths in steps of
// 360 / count in --view's direction. REQUIRES: base.Finalize();
// 1 <= count <= kMaxFrames.
StatusOr<std::vector<Camera>> TurntableCameras(const Camera& base, int count,
                                               const glm::dvec3& centre);

// The camera of frame `index` + 1 of TurntableCameras alone (the same bits),
// made when the frame comes. REQUIRES: 0 <= index < count.
StatusOr<Camera> TurntableCamera(const Camera& base, int count, const glm::dvec3& centre,
                                 int index);

}  // namespace vox

#endif  // VOX_RENDER_FRAME_SEQUENCE_H_

// The planning half of vox::RunRenderJob (render/job.h): the options, the
// frames of a sequence and the checks of every frame's outputs, cameras and
// sizes, all before the first frame is rendered, in time and memory that do
// not grow with the number of frames a turntable has; then each frame's
// camera and output paths, made when that frame comes.
//
// Thread safety: thread-compatible.
#ifndef VOX_RENDER_INTERNAL_JOB_PLAN_H_
#define VOX_RENDER_INTERNAL_JOB_PLAN_H_

#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "core/util/status.h"
#include "render/camera.h"
#include "render/frame_sequence.h"
#include "render/job.h"
#include "storage/meta.h"

namespace vox::job_internal {

// The frames of a run: the cameras given, how many frames the sequence has
// and which of them this run renders; once the store is open
// (PrepareCameras), what each frame's camera is made from.
struct JobSequence {
  std::vector<Camera> given;  // --cam's or the camera JSON's; empty: the default camera
  std::string source;         // where `given` came from, for messages
  int count = 1;              // frames in the sequence
  FrameRange range;           // the frames this run renders
  int frames() const { return range.last - range.first + 1; }
  // Set by PrepareCameras: an array's cameras (frame n is element n - 1),
  // or the one camera (a turntable's base) and the volume's world-box centre.
  std::vector<Camera> cameras;
  Camera base;
  glm::dvec3 centre{0.0};
};

// One frame's output paths, the patterns expanded.
struct FrameOutputs {
  int number = 1;
  std::string exr, preview, stats;
  std::string save_camera;  // a pattern's expansion, or the plain name on the run's last frame
};

// The options that need no file: refused before anything is opened.
Status CheckJobOptions(const RenderJobOptions& options);

// Reads the cameras (before the store is opened: their number decides the
// outputs) and the frames to render. `keep`: the image is kept in memory,
// which holds one frame.
StatusOr<JobSequence> PlanSequence(const RenderJobOptions& options, bool keep);

// The outputs' patterns where a sequence needs them, each writable, with its
// format's extension, and none an input or another output of any frame of
// the run (CheckFrameOutputs): all refused before any work.
Status CheckJobOutputs(const RenderJobOptions& options, const JobSequence& seq);

// Frame `number`'s outputs.
FrameOutputs FrameFiles(const RenderJobOptions& options, const JobSequence& seq, int number);

// Frame `files.number`'s paths checked again when it comes: writable, and
// distinct from the inputs and each other by identity (links).
Status CheckFrameFiles(const RenderJobOptions& options, const JobSequence& seq,
                       const FrameOutputs& files);

// The cameras once the store's bounds are known: each of an array's (their
// distance checked), or the one camera; then every frame of the run checked
// for its size, its tiles and its EXR's room on disk (CheckFrameSize), before
// the first is rendered. A turntable's frames share the base's size.
Status PrepareCameras(const RenderJobOptions& options, const StoreMeta& meta, JobSequence* seq);

// Frame `number`'s camera. REQUIRES: PrepareCameras succeeded.
StatusOr<Camera> FrameCamera(const RenderJobOptions& options, const JobSequence& seq, int number);

// A frame over kMaxPixelsUnlessAllowed is refused without --allow-huge;
// the EXR's uncompressed size (an upper bound) is printed (`say`) and must
// fit the free space of its directory.
Status CheckFrameSize(const RenderJobOptions& options, const std::string& exr_path,
                      const Camera& camera, bool say);

// --save-cam's text for frame `number`: its camera with a pattern or a
// single frame, else (on the run's last frame) the array of the cameras of
// the frames rendered.
StatusOr<std::string> SaveCameraText(const RenderJobOptions& options, const JobSequence& seq,
                                     int number);

}  // namespace vox::job_internal

#endif  // VOX_RENDER_INTERNAL_JOB_PLAN_H_

// vox-view's "Save": the last refined frame as vox-render's files, cam.json
// and scene.json, and the vox-render command line that renders that frame
// again; with --out DIR the server also writes them there, under fresh names
// (view-NNN.cam.json, view-NNN.scene.json, view-NNN.sh), published together
// from temporaries (core/util/atomic_file.h): never over an input, another
// output or a file that appeared meanwhile.
//
// Thread safety: thread-compatible.
#ifndef VOX_TOOLS_VIEW_SAVES_H_
#define VOX_TOOLS_VIEW_SAVES_H_

#include <string>

#include "core/util/status.h"
#include "render/scene.h"

namespace vox {

struct SaveTarget {
  std::string store_dir;   // the store vox-view serves (an input)
  std::string scene_path;  // --scene (an input); empty: none
  std::string out_dir;     // --out; empty: nothing is written
};

// OkStatus when `target.out_dir` is empty, or an existing writable directory
// that is neither the store nor inside it.
Status CheckSaveTarget(const SaveTarget& target);

// `scene` as scene.json text vox-render reads back to the same scene: the
// default key light (no "lights" key) stays the default.
std::string SceneFileText(const Scene& scene);

// {"camera": cam.json text, "scene": scene.json text, "lod": F, "command":
// the vox-render command line, "written": [the files written under --out]}.
StatusOr<std::string> SaveView(const SaveTarget& target, const std::string& camera_json,
                               const std::string& scene_json, const std::string& lod);

}  // namespace vox

#endif  // VOX_TOOLS_VIEW_SAVES_H_

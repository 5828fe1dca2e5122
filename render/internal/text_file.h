// ReadTextFile: reads a whole (small) text file, for the cam.json and
// scene.json readers. Private to render/.
//
// Thread safety: thread-safe.
#ifndef VOX_RENDER_INTERNAL_TEXT_FILE_H_
#define VOX_RENDER_INTERNAL_TEXT_FILE_H_

#include <string>

#include "core/status.h"

namespace vox {

// The file's bytes; NotFound / IoError name the file.
StatusOr<std::string> ReadTextFile(const std::string& path);

}  // namespace vox

#endif  // VOX_RENDER_INTERNAL_TEXT_FILE_H_

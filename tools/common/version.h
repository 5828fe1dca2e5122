// vox::kVersion and vox::GitDescribe: what `vox-* --version` and the Python
// module's vox.__version__ report. The version is the CMake project's
// (project(vox VERSION ...)); the git description is
// `git describe --always --dirty` of the source tree when the tools were last
// built (cmake/VoxGitDescribe.cmake), "unknown" outside a git checkout.
//
// Thread safety: constants.
#ifndef VOX_TOOLS_COMMON_VERSION_H_
#define VOX_TOOLS_COMMON_VERSION_H_

#include <string>

namespace vox {

// "0.9.0".
extern const char* const kVersion;

// "1a7f09f", "v0.9.0-3-g1a7f09f-dirty" or "unknown".
extern const char* const kGitDescribe;

// "vox-render 0.9.0 (git 1a7f09f)": the line `program --version` prints.
std::string VersionLine(const std::string& program);

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_VERSION_H_

#include "tools/common/version.h"

#include "vox_git_describe.h"  // generated into the build tree (tools/common/CMakeLists.txt)

namespace vox {

const char* const kVersion = VOX_PROJECT_VERSION;
const char* const kGitDescribe = VOX_GIT_DESCRIBE;

std::string VersionLine(const std::string& program) {
  return program + " " + kVersion + " (git " + kGitDescribe + ")";
}

}  // namespace vox

#include "render/internal/text_file.h"

#include <fstream>
#include <sstream>

namespace vox {

StatusOr<std::string> ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFoundError(path + ": cannot open for reading");
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) return IoError(path + ": read failed");
  return s.str();
}

}  // namespace vox

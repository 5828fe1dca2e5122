#include "core/ray_text.h"

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace vox {

StatusOr<Ray> ParseRayLine(std::string_view line) {
  // Read as a C string below: a NUL would hide the rest of the line.
  if (line.find('\0') != std::string_view::npos)
    return InvalidArgumentError("the line contains a NUL byte");
  std::string s(line);
  const char* p = s.c_str();
  double v[6];
  for (int i = 0; i < 6; ++i) {
    while (*p == ' ' || *p == '\t') ++p;
    if (*p == '\0' || *p == '\r' || *p == '\n')
      return InvalidArgumentError("expected 6 numbers (ox oy oz dx dy dz), found " +
                                  std::to_string(i));
    char* end = nullptr;
    errno = 0;
    v[i] = std::strtod(p, &end);
    if (end == p || (*end != '\0' && *end != ' ' && *end != '\t' && *end != '\r' && *end != '\n'))
      return InvalidArgumentError("number " + std::to_string(i + 1) + " is not a number: '" +
                                  std::string(p, strcspn(p, " \t\r\n")) + "'");
    p = end;
  }
  while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n') ++p;
  if (*p != '\0') return InvalidArgumentError("more than 6 numbers on the line");
  return Ray{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
}

std::string FormatHitLine(const glm::i64vec3* voxel, double t) {
  if (voxel == nullptr) return "miss";
  char buf[160];
  std::snprintf(buf, sizeof buf, "hit %lld %lld %lld %.17g", (long long)voxel->x,
                (long long)voxel->y, (long long)voxel->z, t);
  return buf;
}

}  // namespace vox

// Text form of rays for vox-probe and tests: one ray per line,
// "ox oy oz dx dy dz", decimal or C99 hex floats, blank lines and lines
// starting with '#' ignored by the caller. Thread-safe.
#ifndef VOX_CORE_RAY_TEXT_H_
#define VOX_CORE_RAY_TEXT_H_

#include <string>
#include <string_view>

#include "core/ray.h"
#include "core/util/status.h"

namespace vox {

// Parses exactly six numbers; names what is wrong otherwise. Does not
// validate the ray (see ValidateRay).
StatusOr<Ray> ParseRayLine(std::string_view line);

// "hit i j k t" (t with 17 significant digits) or "miss".
std::string FormatHitLine(const glm::i64vec3* voxel, double t);

}  // namespace vox

#endif  // VOX_CORE_RAY_TEXT_H_

// Placement of an occupied bbox in a store's octree: the levels (from
// "auto" or "N1+N2") and the origin. Pure integer arithmetic, no OpenVDB.
//
// origin = occupied bbox min aligned down to the brick size
// 2^(levels - brick_level); levels = the smallest N that covers the bbox.
// "auto" chooses 32^3 bricks (5 brick levels), at least one level above
// them, and at most 20 levels above them (more brick levels for huge grids).
//
// Thread safety: stateless functions; thread-safe.
#ifndef VOX_INGEST_PLACEMENT_H_
#define VOX_INGEST_PLACEMENT_H_

#include <cstdint>
#include <string_view>

#include "core/util/status.h"

namespace vox {

// Where the levels come from: `levels` "auto" or "N1+N2".
struct LevelsChoice {
  bool automatic = true;
  int brick_level = 0;  // N1 when !automatic
  int brick_depth = 0;  // N2 when !automatic: levels inside a brick
};
// The one parser of --levels (vox-ingest's and vox-gen's). A brick holds
// at least `min_brick_depth` levels: 1 for vox-ingest; vox-gen also writes
// stores without bricks (N2 = 0).
StatusOr<LevelsChoice> ParseLevels(std::string_view text, int min_brick_depth = 1);

// Integer placement of an occupied index bbox (inclusive) under a choice.
// For an empty bbox (min > max) gives origin 0.
struct Placement {
  int64_t origin[3] = {0, 0, 0};
  int levels = 0;
  int brick_level = 0;
};
StatusOr<Placement> PlaceGrid(const int64_t bbox_min[3], const int64_t bbox_max[3],
                              const LevelsChoice& choice);

}  // namespace vox

#endif  // VOX_INGEST_PLACEMENT_H_

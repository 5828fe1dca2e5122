// Placement: levels and origin. See placement.h.
#include "ingest/placement.h"

#include <algorithm>
#include <string>

#include "core/octree.h"

namespace vox {
namespace {

// Smallest n with 2^n >= extent (extent >= 1).
int CeilLog2(uint64_t extent) {
  int n = 0;
  while ((uint64_t(1) << n) < extent) ++n;
  return n;
}

int64_t AlignDown(int64_t v, int b) { return (v >> b) << b; }  // arithmetic shift: floor

}  // namespace

StatusOr<LevelsChoice> ParseLevels(std::string_view text, int min_brick_depth) {
  LevelsChoice c;
  if (text == "auto") return c;
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("--levels " + std::string(text) + ": " + why +
                                " (expected auto or N1+N2, e.g. 12+5)");
  };
  size_t plus = text.find('+');
  if (plus == std::string_view::npos) return bad("no '+'");
  auto num = [](std::string_view s, int* out) {
    if (s.empty() || s.size() > 3) return false;
    int v = 0;
    for (char ch : s) {
      if (ch < '0' || ch > '9') return false;
      v = v * 10 + (ch - '0');
    }
    *out = v;
    return true;
  };
  int n1 = 0, n2 = 0;
  if (!num(text.substr(0, plus), &n1) || !num(text.substr(plus + 1), &n2))
    return bad("N1 and N2 must be whole numbers");
  if (n1 < 1) return bad("each step needs at least one level");
  if (n2 < min_brick_depth)
    return bad(min_brick_depth == 1 ? "each step needs at least one level"
                                    : "a brick holds at least " + std::to_string(min_brick_depth) +
                                          " levels");
  if (n1 > kMaxStepLevels || n2 > kMaxStepLevels) return bad("each step holds at most 20 levels");
  if (n1 + n2 > kMaxLevels) return bad("at most 40 levels in all");
  c.automatic = false;
  c.brick_level = n1;
  c.brick_depth = n2;
  return c;
}

StatusOr<Placement> PlaceGrid(const int64_t bmin[3], const int64_t bmax[3],
                              const LevelsChoice& choice) {
  Placement p;
  const bool empty = bmin[0] > bmax[0] || bmin[1] > bmax[1] || bmin[2] > bmax[2];
  constexpr int kAutoBrickDepth = 5;
  int b = choice.automatic ? kAutoBrickDepth : choice.brick_depth;
  if (empty) {
    p.brick_level = choice.automatic ? 1 : choice.brick_level;
    p.levels = p.brick_level + b;
    return p;
  }
  for (;;) {
    uint64_t extent = 1;
    for (int a = 0; a < 3; ++a) {
      p.origin[a] = AlignDown(bmin[a], b);
      extent = std::max<uint64_t>(extent, uint64_t(bmax[a] - p.origin[a] + 1));
    }
    const int cover = CeilLog2(extent);
    if (!choice.automatic) {
      p.levels = choice.brick_level + b;
      p.brick_level = choice.brick_level;
      if (cover > p.levels)
        return InvalidArgumentError(
            "--levels " + std::to_string(choice.brick_level) + "+" + std::to_string(b) +
            " covers 2^" + std::to_string(p.levels) + " voxels per axis, but the occupied bbox "
            "(with the origin aligned to the brick size) needs 2^" + std::to_string(cover));
      return p;
    }
    p.levels = std::max(cover, b + 1);
    if (p.levels > kMaxLevels)
      return InvalidArgumentError("the occupied bbox needs 2^" + std::to_string(p.levels) +
                                  " voxels per axis; vox handles at most 2^40");
    if (p.levels - b > kMaxStepLevels) {
      b = p.levels - kMaxStepLevels;  // deeper bricks; realign and measure again
      continue;
    }
    p.brick_level = p.levels - b;
    return p;
  }
}

}  // namespace vox

#include "core/tracer.h"

#include <string>

namespace vox {

StatusOr<int> ParseSplit(const std::string& text, int levels) {
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("split '" + text + "': " + why);
  };
  size_t plus = text.find('+');
  auto parse = [](const std::string& s, int* out) {
    if (s.empty() || s.size() > 3 || s.find_first_not_of("0123456789") != std::string::npos)
      return false;
    *out = std::stoi(s);
    return true;
  };
  int n1 = 0, n2 = 0;
  if (!parse(text.substr(0, plus), &n1)) return bad("expected N1+N2 or N1, e.g. 6+5");
  if (plus != std::string::npos) {
    if (!parse(text.substr(plus + 1), &n2)) return bad("expected N1+N2 or N1, e.g. 6+5");
    if (n1 + n2 != levels)
      return bad("the octree has " + std::to_string(levels) + " levels, not " +
                 std::to_string(n1 + n2));
  }
  if (n1 < 1 || n1 > levels)
    return bad("first-step levels must be 1.." + std::to_string(levels));
  if (n1 > kMaxStepLevels || levels - n1 > kMaxStepLevels)
    return bad("each step holds at most 20 levels");
  return n1;
}

}  // namespace vox

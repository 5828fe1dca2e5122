// The outputs of a frame sequence checked once for all its frames
// (render/frame_sequence.h: MatchFramePattern, CheckFrameOutputs): a frame
// pattern is compared with another pattern, a plain name or an input by the
// shape of its expansions, a few digit counts at a time, never frame by
// frame.
#include <sys/stat.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "core/util/file.h"
#include "render/frame_sequence.h"

namespace vox {
namespace {

// Whether `path` is a frame pattern; `if_bad` for one IsFramePattern refuses.
bool IsPattern(const std::string& path, bool if_bad = false) {
  const StatusOr<bool> p = IsFramePattern("", path);
  return p.ok() ? *p : if_bad;
}

// A path as a frame pattern: `pre`, the number (at least `width` wide,
// padded with '0' or ' '), `post`; `pattern` false: a plain name `pre`.
struct Template {
  std::string pre, post;
  int width = 0;
  bool zero = false;
  bool pattern = false;
};

Template ParseTemplate(const std::string& path) {
  Template t;
  t.pre = path;
  if (!IsPattern(path)) return t;
  t.pattern = true;
  t.pre.clear();
  std::string* part = &t.pre;
  for (size_t i = 0; i < path.size(); ++i) {
    if (path[i] != '%') {
      *part += path[i];
    } else if (path[i + 1] == '%') {
      *part += '%';
      ++i;
    } else {  // the conversion: %d, %Nd or %0Nd
      size_t j = i + 1;
      t.zero = path[j] == '0';
      while (path[j] >= '0' && path[j] <= '9') t.width = t.width * 10 + (path[j++] - '0');
      part = &t.post;
      i = j;  // the 'd'
    }
  }
  return t;
}

std::string Expand(const Template& t, int n) {
  if (!t.pattern) return t.pre;
  char number[128];
  snprintf(number, sizeof number, t.zero ? "%0*d" : "%*d", t.width, n);
  return t.pre + number + t.post;
}

int Match(const Template& t, const std::string& s) {
  if (!t.pattern) return s == t.pre ? -1 : 0;
  if (s.size() <= t.pre.size() + t.post.size() || s.compare(0, t.pre.size(), t.pre) != 0 ||
      s.compare(s.size() - t.post.size(), t.post.size(), t.post) != 0)
    return 0;
  const std::string mid = s.substr(t.pre.size(), s.size() - t.pre.size() - t.post.size());
  const size_t digits = mid.find_first_not_of(t.zero ? "0" : " ");
  if (digits == std::string::npos || mid.size() - digits > 7) return 0;
  int n = 0;
  for (size_t i = digits; i < mid.size(); ++i) {
    if (mid[i] < '0' || mid[i] > '9') return 0;
    n = n * 10 + (mid[i] - '0');
  }
  return n >= 1 && n <= kMaxFrames && Expand(t, n) == s ? n : 0;
}

// The frames of `range` whose number has `k` digits (empty: first > last).
FrameRange Bucket(int k, FrameRange range) {
  int lo = 1, hi = 9;
  for (int i = 1; i < k; ++i) lo *= 10, hi = hi * 10 + 9;
  return {std::max(range.first, lo), std::min(range.last, hi)};
}

int64_t FloorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
int64_t CeilDiv(int64_t a, int64_t b) { return -FloorDiv(-a, b); }

// Frames n of a and m of b in `range` whose expansions are equal, if any
// ({0, 0}: none). Per pair of digit counts the two expansions align
// character by character: a's digits facing b's fixed characters are
// known, and so are b's; where the two numbers overlap they share digits x.
// Then n = PA + x 10^ea and m = PB + x 10^eb, each in its range: an
// interval of x, solved exactly.
std::pair<int, int> Collide(const Template& a, const Template& b, FrameRange range) {
  if (!a.pattern || !b.pattern) {
    const Template& p = a.pattern ? a : b;
    const int n = Match(p, (a.pattern ? b : a).pre);
    if (n >= range.first && n <= range.last)
      return a.pattern ? std::pair{n, -1} : std::pair{-1, n};
    return {0, 0};
  }
  for (int ka = 1; ka <= 7; ++ka)
    for (int kb = 1; kb <= 7; ++kb) {
      const FrameRange ra = Bucket(ka, range), rb = Bucket(kb, range);
      if (ra.first > ra.last || rb.first > rb.last) continue;
      const std::string sa = Expand(a, ra.first), sb = Expand(b, rb.first);
      if (sa.size() != sb.size()) continue;
      const int a0 = int(sa.size() - a.post.size()) - ka, b0 = int(sb.size() - b.post.size()) - kb;
      const int o0 = std::max(a0, b0), o1 = std::max(o0, std::min(a0 + ka, b0 + kb));
      bool fits = true;
      int64_t pa = 0, pb = 0;  // the known digits, the shared ones 0
      for (int i = 0; i < int(sa.size()) && fits; ++i) {
        const bool da = i >= a0 && i < a0 + ka, db = i >= b0 && i < b0 + kb;
        if (!da && !db) fits = sa[i] == sb[i];
        else if (da && !db) fits = sb[i] >= '0' && sb[i] <= '9';
        else if (db && !da) fits = sa[i] >= '0' && sa[i] <= '9';
        if (da) pa = pa * 10 + (db ? 0 : sb[i] - '0');
        if (db) pb = pb * 10 + (da ? 0 : sa[i] - '0');
      }
      if (!fits) continue;
      int64_t ea = 1, eb = 1, span = 1;  // 10^(digits after the shared ones), 10^shared
      for (int i = o1; i < a0 + ka; ++i) ea *= 10;
      for (int i = o1; i < b0 + kb; ++i) eb *= 10;
      for (int i = o0; i < o1; ++i) span *= 10;
      if (o1 == o0) ea = eb = 1;  // nothing shared: x = 0
      const int64_t lo = std::max({int64_t(0), CeilDiv(ra.first - pa, ea), CeilDiv(rb.first - pb, eb)});
      const int64_t hi = std::min({span - 1, FloorDiv(ra.last - pa, ea), FloorDiv(rb.last - pb, eb)});
      if (lo <= hi) return {int(pa + lo * ea), int(pb + lo * eb)};
    }
  return {0, 0};
}

// An output compared by its name in its directory (the directory's device
// and inode), or, with its frame number in a directory, as text.
struct Keyed {
  const NamedPath* out;
  Template name;  // the name, or the whole path as text
  bool by_directory = false;
  dev_t dev = 0;
  ino_t ino = 0;
};

Keyed KeyOf(const NamedPath& out, const FrameRange& range) {
  Keyed k{&out, ParseTemplate(out.path)};
  std::string raw_dir, raw_name;
  SplitPath(out.path, &raw_dir, &raw_name);
  if (k.name.pattern && IsPattern(raw_dir, true)) return k;  // text
  std::string dir, name;
  SplitPath(ExpandFramePattern(out.path, range.first), &dir, &name);
  struct stat st;
  if (stat(dir.c_str(), &st) != 0) return k;
  k.name = k.name.pattern ? ParseTemplate(raw_name) : Template{name, "", 0, false, false};
  k.by_directory = true;
  k.dev = st.st_dev;
  k.ino = st.st_ino;
  return k;
}

std::string FramePath(const NamedPath& p, int n, const FrameRange& range) {
  const bool pattern = IsPattern(p.path);
  const std::string frame =
      pattern || range.first != range.last ? "frame " + std::to_string(n > 0 ? n : range.last) + "'s "
                                           : "";
  return frame + p.role + " " + ExpandFramePattern(p.path, n > 0 ? n : range.last);
}

}  // namespace

int MatchFramePattern(const std::string& pattern, const std::string& path) {
  return Match(ParseTemplate(pattern), path);
}

Status CheckFrameOutputs(const std::vector<NamedPath>& inputs,
                         const std::vector<NamedPath>& outputs, FrameRange range) {
  namespace fs = std::filesystem;
  std::vector<Keyed> keyed;
  std::vector<NamedPath> plain;
  for (const NamedPath& out : outputs) {
    if (out.path.empty()) continue;
    if (!IsPattern(out.path)) plain.push_back(out);
    keyed.push_back(KeyOf(out, range));
  }
  VOX_RETURN_IF_ERROR(CheckDistinctPaths(inputs, plain));  // by identity
  for (size_t i = 0; i < keyed.size(); ++i)
    for (size_t j = i + 1; j < keyed.size(); ++j) {
      const Keyed &a = keyed[i], &b = keyed[j];
      if (!a.name.pattern && !b.name.pattern) continue;  // compared above
      if (a.by_directory != b.by_directory) continue;
      if (a.by_directory && (a.dev != b.dev || a.ino != b.ino)) continue;
      const auto [n, m] = Collide(a.name, b.name, range);
      if (n != 0)
        return InvalidArgumentError(FramePath(*a.out, n, range) + " and " +
                                    FramePath(*b.out, m, range) +
                                    " are the same file; give each output its own path");
    }
  // An input is checked as given and as its real path (a link's target).
  for (const NamedPath& in : inputs) {
    std::error_code ec;
    if (in.path.empty() || !fs::exists(in.path, ec)) continue;
    const std::string real = fs::canonical(in.path, ec).string();
    for (const std::string& path : {in.path, real}) {
      std::string dir, name;
      SplitPath(path, &dir, &name);
      struct stat st;
      const bool dir_known = stat(dir.c_str(), &st) == 0;
      for (const Keyed& out : keyed) {
        if (!out.name.pattern) continue;  // compared above
        if (out.by_directory && !(dir_known && out.dev == st.st_dev && out.ino == st.st_ino))
          continue;
        const int n = Match(out.name, out.by_directory ? name : path);
        if (n >= range.first && n <= range.last)
          return InvalidArgumentError(FramePath(*out.out, n, range) + " is the " + in.role + " " +
                                      in.path + "; writing it would destroy that input");
      }
    }
  }
  return OkStatus();
}

}  // namespace vox

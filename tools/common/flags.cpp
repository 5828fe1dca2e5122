#include "tools/common/flags.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace vox {

FlagReader::FlagReader(int argc, const char* const* argv) {
  for (int i = 1; i < argc; ++i) args_.emplace_back(argv[i]);
}

std::string FlagReader::CommandLine(const std::string& program) const {
  std::string line = program;
  for (const std::string& a : args_) line += " " + a;
  return line;
}

bool FlagReader::Next() {
  if (size_t(pos_ + 1) >= args_.size()) return false;
  ++pos_;
  return true;
}

std::optional<std::string> FlagReader::Value() {
  if (size_t(pos_ + 1) >= args_.size()) return std::nullopt;
  return args_[size_t(++pos_)];
}

bool ParseInt(const std::string& s, int64_t lo, int64_t hi, int64_t* out) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(s.c_str(), &end, 10);
  if (end == s.c_str() || *end != '\0' || errno != 0 || v < lo || v > hi) return false;
  *out = int64_t(v);
  return true;
}

bool ParseInt(const std::string& s, int lo, int hi, int* out) {
  int64_t v = 0;
  if (!ParseInt(s, int64_t(lo), int64_t(hi), &v)) return false;
  *out = int(v);
  return true;
}

bool ParseDouble(const std::string& s, double* out) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || errno != 0 || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

std::vector<std::string> SplitList(const std::string& s, char sep) {
  std::vector<std::string> items;
  size_t start = 0;
  for (;;) {
    const size_t at = s.find(sep, start);
    items.push_back(s.substr(start, at == std::string::npos ? std::string::npos : at - start));
    if (at == std::string::npos) return items;
    start = at + 1;
  }
}

}  // namespace vox

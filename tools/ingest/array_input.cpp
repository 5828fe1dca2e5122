#include "tools/ingest/array_input.h"

#include <cstdlib>
#include <cstring>
#include <memory>

#include "tools/common/cli.h"
#include "tools/common/options.h"

namespace vox {

namespace {

bool EndsWith(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// "X,Y,Z" -> three integers (positive when `positive`).
bool ParseTriple(const std::string& text, bool positive, std::array<int64_t, 3>* out) {
  const char* p = text.c_str();
  for (int a = 0; a < 3; ++a) {
    char* end = nullptr;
    const long long v = std::strtoll(p, &end, 10);
    if (end == p || (positive && v <= 0)) return false;
    (*out)[size_t(a)] = v;
    p = end;
    if (a < 2) {
      if (*p != ',' && *p != 'x') return false;
      ++p;
    }
  }
  return *p == '\0';
}

}  // namespace

ArrayInput PrepareArrayInput(int argc, char** argv) {
  ArrayInput in;
  std::string shape_text, dtype, origin_text;
  ArrayPlacement& place = in.placement;
  std::vector<std::string> rest;
  std::vector<size_t> positional;  // indices into rest
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool ours = a == "--shape" || a == "--dtype" || a == "--voxel-size" || a == "--origin";
    if (ours) {
      in.wanted = true;
      if (i + 1 >= argc) {
        in.error = a + " needs a value";
        return in;
      }
      const std::string v = argv[++i];
      if (a == "--shape") shape_text = v;
      if (a == "--dtype") dtype = v;
      if (a == "--origin") origin_text = v;
      if (a == "--voxel-size") {
        char* end = nullptr;
        place.voxel_size = std::strtod(v.c_str(), &end);
        if (end == v.c_str() || *end != '\0' || !(place.voxel_size > 0)) {
          in.error = "--voxel-size takes a positive number, not '" + v + "'";
          return in;
        }
      }
      continue;
    }
    if (a.empty() || a[0] != '-') positional.push_back(rest.size());
    rest.push_back(a);
    // A flag's value is no input or output (--flag=value carries its own).
    if (a.size() > 1 && a[0] == '-' && a.find('=') == std::string::npos && i + 1 < argc &&
        ArityOf(IngestOptionTable(), a) == FlagArity::kValue)
      rest.push_back(argv[++i]);
  }
  if (positional.size() != 2) {
    if (in.wanted) in.error = "an array input takes an input file and an output store";
    return in;
  }
  const std::string input = rest[positional[0]];
  const bool npy = EndsWith(input, ".npy");
  if (!npy && !EndsWith(input, ".raw") && !in.wanted) return in;  // a .vdb
  in.wanted = true;
  if (!origin_text.empty() && !ParseTriple(origin_text, false, &place.origin)) {
    in.error = "--origin takes X,Y,Z (integers, index units), not '" + origin_text + "'";
    return in;
  }
  if (npy) {
    if (!shape_text.empty() || !dtype.empty()) {
      in.error = "a .npy file carries its shape and dtype: no --shape or --dtype";
      return in;
    }
    auto m = MappedArray::OpenNpy(input);
    if (!m.ok()) {
      in.error = m.status().message();
      in.exit_code = 1;
      return in;
    }
    in.array = std::move(m).value();
  } else {
    std::array<int64_t, 3> shape{};
    if (!ParseTriple(shape_text, true, &shape) || dtype.empty()) {
      in.error = "a raw file '" + input + "' needs --shape X,Y,Z and --dtype (e.g. float32)";
      return in;
    }
    auto m = MappedArray::OpenRaw(input, shape, dtype);
    if (!m.ok()) {
      in.error = m.status().message();
      in.exit_code = 1;
      return in;
    }
    in.array = std::move(m).value();
  }
  in.args.push_back(argv[0]);
  in.args.insert(in.args.end(), rest.begin(), rest.end());
  return in;
}

}  // namespace vox

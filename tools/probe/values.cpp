#include "tools/probe/values.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "core/util/atomic_file.h"
#include "storage/sample.h"

namespace vox {

namespace {

constexpr const char* kUsage =
    "usage: vox-probe STORE --at X Y Z [--at X Y Z ...] [--world] [--trilinear] [--level L]\n"
    "       vox-probe STORE --slice AXIS INDEX -o OUT.exr [--attr NAME] [--level L] [--max-mb M]\n"
    "--at: the store's values at index-space points (voxel i j k is [i, i+1) x [j, j+1) x\n"
    "[k, k+1): an OpenVDB index point + 0.5; --world: the VDB's world space), one line each:\n"
    "'X Y Z inside|outside occupancy V [density V] [coverage V] [color R G B] [normal X Y Z]'.\n"
    "--slice: the plane AXIS (x, y, z) = INDEX over the occupied box of the other two axes\n"
    "as an EXR: one channel per component (NAME, or NAME.X NAME.Y NAME.Z), pixel (column c,\n"
    "row r) the voxel at the box's corner + (c, r) along the other axes in order; the\n"
    "corner is the vox:slice_origin attribute. Values are 0 where unoccupied.\n";

int Usage(const std::string& message) {
  std::fprintf(stderr, "vox-probe: %s\n%s", message.c_str(), kUsage);
  return 2;
}

bool ParseDouble(const char* s, double* out) {
  char* end = nullptr;
  *out = std::strtod(s, &end);
  return end != s && *end == '\0' && std::isfinite(*out);
}

bool ParseInt(const char* s, long long* out) {
  char* end = nullptr;
  *out = std::strtoll(s, &end, 10);
  return end != s && *end == '\0';
}

struct ValueArgs {
  std::string store, out, attr;
  std::vector<glm::dvec3> points;
  bool world = false, trilinear = false;
  int axis = -1;
  long long index = 0, level = 0;
  double max_mb = 1024;
};

// Parses the command line into *a; returns an error message or "".
std::string Parse(int argc, char** argv, ValueArgs* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string f = argv[i];
    auto need = [&](int n) { return i + n < argc; };
    if (f == "--at") {
      glm::dvec3 p;
      if (!need(3) || !ParseDouble(argv[i + 1], &p.x) || !ParseDouble(argv[i + 2], &p.y) ||
          !ParseDouble(argv[i + 3], &p.z))
        return "--at takes three finite numbers X Y Z";
      a->points.push_back(p);
      i += 3;
    } else if (f == "--slice") {
      const std::string ax = need(2) ? argv[i + 1] : "";
      a->axis = ax == "x" || ax == "0" ? 0 : ax == "y" || ax == "1" ? 1 : ax == "z" || ax == "2" ? 2 : -1;
      if (a->axis < 0 || !ParseInt(argv[i + 2], &a->index)) return "--slice takes AXIS (x, y or z) and INDEX";
      i += 2;
    } else if (f == "-o" || f == "--attr" || f == "--level" || f == "--max-mb") {
      if (!need(1)) return f + " needs a value";
      const char* v = argv[++i];
      if (f == "-o") a->out = v;
      if (f == "--attr") a->attr = v;
      if (f == "--level" && (!ParseInt(v, &a->level) || a->level < 0 || a->level > 30))
        return "--level takes 0 .. 30";
      if (f == "--max-mb" && (!ParseDouble(v, &a->max_mb) || a->max_mb <= 0))
        return "--max-mb takes a positive number";
    } else if (f == "--world") {
      a->world = true;
    } else if (f == "--trilinear") {
      a->trilinear = true;
    } else if (!f.empty() && f[0] == '-') {
      return "unknown flag '" + f + "' with --at or --slice";
    } else if (a->store.empty()) {
      a->store = f;
    } else {
      return "more than one store given";
    }
  }
  if (a->store.empty()) return "give a store directory";
  if (a->points.empty() == (a->axis < 0)) return "give --at or --slice, not both";
  if (a->axis >= 0 && a->out.empty()) return "--slice needs -o OUT.exr";
  if (a->axis < 0 && (!a->out.empty() || !a->attr.empty())) return "-o and --attr go with --slice";
  return "";
}

int PrintAt(StoreValues& v, const ValueArgs& a) {
  std::vector<glm::dvec3> pts = a.points;
  if (a.world)
    for (auto& p : pts) p = v.WorldToIndex(p);
  auto s = v.Sample(pts, a.trilinear ? SampleMode::kTrilinear : SampleMode::kNearest);
  if (!s.ok()) {
    std::fprintf(stderr, "vox-probe: %s\n", s.status().ToString().c_str());
    return 1;
  }
  for (size_t i = 0; i < pts.size(); ++i) {
    std::string line;
    char buf[160];
    std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g %s occupancy %.9g", a.points[i].x, a.points[i].y,
                  a.points[i].z, s->inside[i] ? "inside" : "outside", s->occupancy[i]);
    line = buf;
    auto one = [&](const char* name, const std::vector<float>& f) {
      if (f.empty()) return;
      std::snprintf(buf, sizeof buf, " %s %.9g", name, f[i]);
      line += buf;
    };
    auto three = [&](const char* name, const std::vector<float>& f) {
      if (f.empty()) return;
      std::snprintf(buf, sizeof buf, " %s %.9g %.9g %.9g", name, f[3 * i], f[3 * i + 1], f[3 * i + 2]);
      line += buf;
    };
    one("density", s->density);
    one("coverage", s->coverage);
    three("color", s->color);
    three("normal", s->normal);
    std::puts(line.c_str());
  }
  return 0;
}

Status WriteSliceExr(const std::string& path, int width, int height, int comps, const std::string& name,
                     const std::vector<float>& planar, const std::string& origin) {
  VOX_ASSIGN_OR_RETURN(AtomicFile file, AtomicFile::Create(path));
  try {
    Imf::Header header(width, height);
    header.insert("vox:slice_origin", Imf::StringAttribute(origin));
    Imf::FrameBuffer fb;
    static const char* kAxis[3] = {".X", ".Y", ".Z"};
    for (int c = 0; c < comps; ++c) {
      const std::string ch = comps == 1 ? name : name + kAxis[c];
      header.channels().insert(ch, Imf::Channel(Imf::FLOAT));
      fb.insert(ch, Imf::Slice(Imf::FLOAT, (char*)(planar.data() + size_t(c) * width * height),
                               sizeof(float), sizeof(float) * size_t(width)));
    }
    Imf::OutputFile out(file.temp_path().c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(height);
  } catch (const std::exception& e) {
    return IoError("cannot write '" + path + "': " + e.what());
  }
  return file.Commit();
}

int WriteSlice(StoreValues& v, const ValueArgs& a) {
  ValueAttr attr = DefaultValueAttr(v.meta());
  if (!a.attr.empty()) {
    auto p = ParseValueAttr(a.attr, v.meta());
    if (!p.ok()) {  // an attribute the store does not keep: the store cannot serve it
      std::fprintf(stderr, "vox-probe: --attr %s (store '%s')\n", p.status().message().c_str(),
                   a.store.c_str());
      return 1;
    }
    attr = *p;
  }
  glm::i64vec3 lo, hi;
  v.OccupiedBox(&lo, &hi);
  lo[a.axis] = a.index;
  hi[a.axis] = a.index + 1;
  const int u = a.axis == 0 ? 1 : 0, w = a.axis == 2 ? 1 : 2;  // columns, rows
  const uint64_t bytes = StoreValues::ReadBytes(lo, hi, attr);
  if (double(bytes) > a.max_mb * (1 << 20)) {
    std::fprintf(stderr, "vox-probe: the slice is %llu MiB, above --max-mb %g\n",
                 (unsigned long long)(bytes >> 20), a.max_mb);
    return 1;
  }
  const int comps = ValueAttrComponents(attr);
  std::vector<float> box(bytes / sizeof(float));
  Status st = v.Read(lo, hi, attr, box.data());
  const int width = int(hi[u] - lo[u]), height = int(hi[w] - lo[w]);
  if (st.ok() && (width == 0 || height == 0)) st = InvalidArgumentError("the store is empty: no slice to write");
  if (st.ok()) {
    // box is [x][y][z][c] with one index fixed; the EXR wants [c][row][column].
    std::vector<float> planar(box.size());
    const glm::i64vec3 n = hi - lo;
    for (int64_t x = 0; x < n.x; ++x)
      for (int64_t y = 0; y < n.y; ++y)
        for (int64_t z = 0; z < n.z; ++z) {
          const glm::i64vec3 d(x, y, z);
          const size_t src = size_t((x * n.y + y) * n.z + z) * comps;
          for (int c = 0; c < comps; ++c)
            planar[(size_t(c) * height + size_t(d[w])) * width + size_t(d[u])] = box[src + c];
        }
    const std::string origin = std::to_string(lo.x) + " " + std::to_string(lo.y) + " " + std::to_string(lo.z);
    st = WriteSliceExr(a.out, width, height, comps, ValueAttrName(attr), planar, origin);
  }
  if (!st.ok()) {
    std::fprintf(stderr, "vox-probe: %s\n", st.ToString().c_str());
    return 1;
  }
  std::fprintf(stderr, "vox-probe: wrote %s (%d x %d, %s, corner %lld %lld %lld)\n", a.out.c_str(), width,
               height, ValueAttrName(attr), (long long)lo.x, (long long)lo.y, (long long)lo.z);
  return 0;
}

}  // namespace

bool WantsValues(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--at" || std::string(argv[i]) == "--slice") return true;
  return false;
}

int RunValues(int argc, char** argv) {
  ValueArgs a;
  const std::string error = Parse(argc, argv, &a);
  if (!error.empty()) return Usage(error);
  auto v = StoreValues::Open(a.store, int(a.level), uint64_t(256) << 20);
  if (!v.ok()) {  // a store (or --level) that cannot be read: a failure, as in every tool
    std::fprintf(stderr, "vox-probe: %s\n", v.status().ToString().c_str());
    return 1;
  }
  return a.axis >= 0 ? WriteSlice(**v, a) : PrintAt(**v, a);
}

}  // namespace vox

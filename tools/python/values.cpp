// vox.sample, vox.read and vox.slice: a store's values at points, in boxes
// and in slices as numpy arrays, over storage/sample.h (read out of core
// through the store's brick cache, cache_mb per store); and the conversion
// under vox.ingest_array (__init__.py.in), over ingest/array_ingest.h.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "ingest/array_ingest.h"
#include "storage/sample.h"
#include "tools/python/bindings.h"

namespace voxpy {

namespace {

std::unique_ptr<vox::StoreValues> OpenValues(const py::object& store, int level, double cache_mb) {
  if (!(cache_mb > 0)) throw py::value_error("cache_mb must be positive");
  const std::string path = PathOf(store);
  std::optional<vox::StatusOr<std::unique_ptr<vox::StoreValues>>> v;
  {
    py::gil_scoped_release release;
    v.emplace(vox::StoreValues::Open(path, level, uint64_t(cache_mb * (1 << 20))));
  }
  CheckRun(v->status());
  return std::move(*v).value();
}

py::dict Sample(const py::object& store, const py::object& points_in, int level,
                const std::string& space, const std::string& mode, double cache_mb) {
  if (space != "index" && space != "world") throw py::value_error("space must be 'index' or 'world', not '" + space + "'");
  if (mode != "nearest" && mode != "trilinear")
    throw py::value_error("mode must be 'nearest' or 'trilinear', not '" + mode + "'");
  auto pts = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(points_in);
  if (!pts || pts.ndim() != 2 || pts.shape(1) != 3) throw py::value_error("points must be an (N, 3) array");
  auto values = OpenValues(store, level, cache_mb);
  const py::ssize_t n = pts.shape(0);
  std::vector<glm::dvec3> p(static_cast<size_t>(n));
  for (py::ssize_t i = 0; i < n; ++i) {
    p[size_t(i)] = {pts.at(i, 0), pts.at(i, 1), pts.at(i, 2)};
    if (space == "world") p[size_t(i)] = values->WorldToIndex(p[size_t(i)]);
  }
  std::optional<vox::StatusOr<vox::Samples>> r;
  {
    py::gil_scoped_release release;
    r.emplace(values->Sample(p, mode == "nearest" ? vox::SampleMode::kNearest : vox::SampleMode::kTrilinear));
  }
  auto& s = *r;
  if (!s.ok()) Raise(s.status().code(), "points: " + s.status().message());
  py::dict d;
  d["inside"] = Owned(std::move(s->inside), {n}).attr("astype")("bool");
  d["occupancy"] = Owned(std::move(s->occupancy), {n});
  if (!s->density.empty()) d["density"] = Owned(std::move(s->density), {n});
  if (!s->coverage.empty()) d["coverage"] = Owned(std::move(s->coverage), {n});
  if (!s->color.empty()) d["color"] = Owned(std::move(s->color), {n, 3});
  if (!s->normal.empty()) d["normal"] = Owned(std::move(s->normal), {n, 3});
  return d;
}

std::string Gib(uint64_t bytes) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3g GiB", double(bytes) / double(1ull << 30));
  return buf;
}

py::array ReadBox(vox::StoreValues& values, const glm::i64vec3& lo, const glm::i64vec3& hi,
                  const py::object& attr_name, uint64_t max_bytes) {
  vox::ValueAttr attr = vox::DefaultValueAttr(values.meta());
  if (!attr_name.is_none()) {
    auto a = vox::ParseValueAttr(py::str(attr_name).cast<std::string>(), values.meta());
    CheckUsage(a.status());
    attr = *a;
  }
  for (int c = 0; c < 3; ++c)
    if (hi[c] < lo[c]) throw py::value_error("bbox: x1, y1, z1 must not be below x0, y0, z0");
  const uint64_t bytes = vox::StoreValues::ReadBytes(lo, hi, attr);
  if (bytes > max_bytes) {
    const glm::i64vec3 n = hi - lo;
    Raise(vox::StatusCode::kResourceExhausted,
          "the region is " + std::to_string(n.x) + " x " + std::to_string(n.y) + " x " + std::to_string(n.z) +
              (vox::ValueAttrComponents(attr) > 1 ? " x 3" : "") + " float32, " + Gib(bytes) +
              ", above max_bytes (" + Gib(max_bytes) + "): read it in smaller boxes or raise max_bytes");
  }
  std::vector<float> out;
  vox::Status st;
  {
    py::gil_scoped_release release;
    try {
      out.resize(bytes / sizeof(float));
    } catch (const std::bad_alloc&) {
      st = vox::ResourceExhaustedError("no memory for the region (" + Gib(bytes) + ")");
    }
    if (st.ok()) st = values.Read(lo, hi, attr, out.data());
  }
  CheckRun(st);
  std::vector<py::ssize_t> shape = {hi.x - lo.x, hi.y - lo.y, hi.z - lo.z};
  if (vox::ValueAttrComponents(attr) > 1) shape.push_back(3);
  return Owned(std::move(out), shape);
}

glm::i64vec3 Corner(const py::handle& h) {
  auto t = h.cast<std::vector<int64_t>>();
  if (t.size() != 3) throw py::value_error("bbox corners are (x, y, z)");
  return {t[0], t[1], t[2]};
}

py::array Read(const py::object& store, const py::object& bbox, int level, const py::object& attr,
               uint64_t max_bytes, double cache_mb) {
  if (py::len(bbox) != 2) throw py::value_error("bbox is ((x0, y0, z0), (x1, y1, z1))");
  const glm::i64vec3 lo = Corner(bbox[py::int_(0)]), hi = Corner(bbox[py::int_(1)]);
  auto values = OpenValues(store, level, cache_mb);
  return ReadBox(*values, lo, hi, attr, max_bytes);
}

py::array Slice(const py::object& store, const py::object& axis_in, int64_t index, int level,
                const py::object& attr, uint64_t max_bytes, double cache_mb) {
  int axis = -1;
  if (py::isinstance<py::str>(axis_in)) {
    const std::string a = axis_in.cast<std::string>();
    axis = a == "x" ? 0 : a == "y" ? 1 : a == "z" ? 2 : -1;
  } else {
    axis = axis_in.cast<int>();
  }
  if (axis < 0 || axis > 2) throw py::value_error("axis is 0, 1, 2 or 'x', 'y', 'z'");
  auto values = OpenValues(store, level, cache_mb);
  glm::i64vec3 lo, hi;
  values->OccupiedBox(&lo, &hi);
  lo[axis] = index;
  hi[axis] = index + 1;
  py::array a = ReadBox(*values, lo, hi, attr, max_bytes);
  return a.attr("squeeze")(axis);
}

// vox.ingest_array's first half: the array as a fog volume in a .vdb file.
void ArrayToVdb(const py::array& array, const py::object& vdb_path, double voxel_size,
                const std::vector<int64_t>& origin, double threshold) {
  if (array.ndim() != 3) throw py::value_error("the array must be 3-D, not " + std::to_string(array.ndim()) + "-D");
  const bool c_order = (array.flags() & py::array::c_style) != 0;
  const bool f_order = (array.flags() & py::array::f_style) != 0;
  if (!c_order && !f_order) throw py::value_error("the array must be contiguous (numpy.ascontiguousarray)");
  if (origin.size() != 3) throw py::value_error("origin is (x, y, z)");
  vox::ArrayView view;
  view.dtype = py::str(array.dtype().attr("str")).cast<std::string>();
  view.shape = {array.shape(0), array.shape(1), array.shape(2)};
  view.fortran_order = !c_order;
  view.data = array.data();
  vox::ArrayPlacement place;
  place.voxel_size = voxel_size;
  place.origin = {origin[0], origin[1], origin[2]};
  place.threshold = threshold;
  const std::string path = PathOf(vdb_path);
  vox::Status st;
  {
    py::gil_scoped_release release;
    st = vox::ArrayToVdb(view, place, path, "the array");
  }
  CheckUsage(st);
}

}  // namespace

void RegisterValues(py::module_& m) {
  m.def("_array_to_vdb", &ArrayToVdb, py::arg("array"), py::arg("vdb_path"), py::arg("voxel_size"),
        py::arg("origin"), py::arg("threshold"), "vox.ingest_array's conversion; not for direct use.");
  m.def("sample", &Sample, py::arg("store"), py::arg("points"), py::arg("level") = 0,
        py::arg("space") = "index", py::arg("mode") = "nearest", py::arg("cache_mb") = 256.0,
        "Values at points: points is (N, 3), in vox index space (voxel ijk is [ijk, ijk+1): "
        "OpenVDB's index point + 0.5) or, with space='world', in the VDB's world space. "
        "mode='nearest' reads the voxel holding each point; 'trilinear' weighs the 8 voxels "
        "around it (centres at ijk + 0.5, unoccupied ones counting 0), as OpenVDB's BoxSampler. "
        "level > 0 reads the level-of-detail pyramid. Returns {'inside': (N,) bool (False outside "
        "the occupied box, where values are NaN), 'occupancy': (N,) float32, and 'density', "
        "'coverage' (N,), 'color', 'normal' (N, 3) when the store keeps them}.");
  m.def("read", &Read, py::arg("store"), py::arg("bbox"), py::arg("level") = 0,
        py::arg("attr") = py::none(), py::arg("max_bytes") = uint64_t(1) << 30,
        py::arg("cache_mb") = 256.0,
        "A box of voxels as a float32 array: bbox is ((x0, y0, z0), (x1, y1, z1)) in index "
        "coordinates (level > 0: that level's cells), half-open, so the shape is (x1-x0, y1-y0, "
        "z1-z0), plus a trailing 3 for 'color' and 'normal'. attr: 'occupancy', 'density', "
        "'color', 'normal', 'coverage' (default: density for fog, occupancy otherwise); 0 where "
        "unoccupied. Read out of core through a brick cache of cache_mb; a region above "
        "max_bytes is refused (RuntimeError naming its size).");
  m.def("slice", &Slice, py::arg("store"), py::arg("axis"), py::arg("index"), py::arg("level") = 0,
        py::arg("attr") = py::none(), py::arg("max_bytes") = uint64_t(1) << 30,
        py::arg("cache_mb") = 256.0,
        "The plane axis = index (axis 0/1/2 or 'x'/'y'/'z') over the occupied box of the other "
        "two axes (vox.Store(path).info's index bbox), as vox.read: a 2-D array (plus a "
        "trailing 3 for vectors).");
}

}  // namespace voxpy

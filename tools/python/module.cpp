// The Python module `vox`'s compiled part, `vox._vox` (the package's
// __init__.py, tools/python/__init__.py.in, checks the interpreter and
// re-exports it): bindings over the libraries the command-line tools use, with the tools' options as keyword arguments (applied by
// tools/common/options.h, so values are checked, and refused with the
// messages, exactly as on the command line). Long calls release the GIL.
//
//   vox.ingest(vdb_path, store_path, progress=None, **options) -> dict
//   vox.Store(path)                  .info: vox-info's metadata as a dict
//   vox.render(store, camera=None, scene=None, **options) -> dict of numpy
//       arrays (rgba, z, normal, voxel) and "stats" (the --stats document)
//   vox.probe(store, rays, **options) -> (voxels, t, hit)
//   vox.read_exr(path) -> dict (channels as numpy arrays, string attributes)
//   vox.__version__ ("0.9.0"), vox.__git_describe__ (as `vox-* --version`)
//
// vox.ingest runs the ingest in a child interpreter (ingest_process.h): a
// .vdb that crashes OpenVDB raises RuntimeError instead of ending Python.
//
// A Status becomes ValueError (InvalidArgument, Unsupported), OSError
// (NotFound, IoError, Corruption) or RuntimeError (ResourceExhausted,
// Internal), with the text the tool prints after its name; an allocation
// failure becomes MemoryError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "ingest/limits.h"
#include "render/exr.h"
#include "render/job.h"
#include "storage/store_info.h"
#include "tools/common/options.h"
#include "tools/common/prober.h"
#include "tools/common/version.h"
#include "tools/python/bindings.h"
#include "tools/python/ingest_process.h"
#include "tools/python/polled.h"

namespace py = pybind11;

namespace {

using vox::RunPolled;
using voxpy::CheckRun;
using voxpy::CheckUsage;
using voxpy::Owned;
using voxpy::PathOf;
using voxpy::Raise;

// A keyword argument -> the tool's flag and its text value (None: not given,
// bool: a switch). "o" is -o; "zstd_level" is --zstd-level.
struct KwFlag {
  std::string flag;
  std::optional<std::string> value;  // nullopt: a switch set to False, or None
  bool is_bool = false;
};

KwFlag ToFlag(const std::string& key, const py::handle& v) {
  KwFlag f;
  std::string name = key;
  for (char& c : name)
    if (c == '_') c = '-';
  f.flag = (name.size() == 1 ? "-" : "--") + name;
  if (v.is_none()) return f;
  if (py::isinstance<py::bool_>(v)) {
    f.is_bool = true;
    if (v.cast<bool>()) f.value = "";
    return f;
  }
  if (py::isinstance<py::str>(v)) {
    f.value = v.cast<std::string>();
  } else if (py::isinstance<py::float_>(v)) {
    f.value = py::repr(py::float_(py::reinterpret_borrow<py::object>(v))).cast<std::string>();  // round-trips the double exactly
  } else if (key == "layers" && (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v))) {
    std::string s;
    for (const py::handle& item : v) s += (s.empty() ? "" : ",") + py::str(item).cast<std::string>();
    f.value = s;
  } else if ((key == "size" || key == "tiles" || key == "view") && py::isinstance<py::tuple>(v) &&
             py::len(v) == 2) {
    const py::tuple t = v.cast<py::tuple>();
    f.value = py::str(t[0]).cast<std::string>() +
              (key == "size" ? "x" : key == "view" ? "," : "/") + py::str(t[1]).cast<std::string>();
  } else if (py::hasattr(v, "__fspath__") || py::isinstance<py::bytes>(v)) {
    f.value = PathOf(v);
  } else {
    f.value = py::str(v).cast<std::string>();
  }
  return f;
}

// quiet=: True or False, else the TypeError ApplyKwargs gives a switch.
bool QuietKwarg(const char* fn, const py::handle& v) {
  if (py::isinstance<py::bool_>(v)) return v.cast<bool>();
  throw py::type_error(std::string(fn) + "(): quiet takes True or False");
}

// Applies keyword arguments through a tool's option table (tools/common/options.h,
// the one its command line is built from).
template <class Apply>
void ApplyKwargs(const py::kwargs& kwargs, const char* fn, vox::OptionTable table, Apply apply) {
  for (const auto& [k, v] : kwargs) {
    const std::string key = py::str(k);
    const KwFlag f = ToFlag(key, v);
    const vox::FlagArity a = vox::ArityOf(table, f.flag);
    if (a == vox::FlagArity::kUnknown)
      throw py::type_error(std::string(fn) + "() got an unexpected keyword argument '" + key +
                           "' (no flag " + f.flag + ")");
    if (a == vox::FlagArity::kSwitch && !f.is_bool && f.value)
      throw py::type_error(std::string(fn) + "(): " + key + " takes True or False");
    if (a == vox::FlagArity::kValue && f.is_bool)
      throw py::type_error(std::string(fn) + "(): " + key + " takes a value, not a bool");
    if (f.value) {
      CheckUsage(apply(f.flag, *f.value));
    } else if (f.is_bool && f.flag.rfind("--", 0) == 0) {
      // False for a switch that is on by default: its "--no-" form (prefetch=False).
      const std::string off = "--no-" + f.flag.substr(2);
      if (vox::ArityOf(table, off) == vox::FlagArity::kSwitch) CheckUsage(apply(off, ""));
    }
  }
}

py::object JsonToPython(const std::string& text) {
  return py::module_::import("json").attr("loads")(text);
}

// --- ingest -----------------------------------------------------------------

std::string g_module_name = "vox._vox";  // set on import: the child imports it by name

// Calls a Python progress(bricks_done, bricks_total, voxels_done) from the
// ingest's thread; after it raises, it is not called again and the exception
// is raised when the ingest returns.
// Forwards to `inner` (may be null) and answers Cancelled from `cancel` or
// the inner sink.
class CancelSink : public vox::ProgressSink {
 public:
  CancelSink(vox::ProgressSink* inner, const std::atomic<bool>* cancel)
      : inner_(inner), cancel_(cancel) {}
  void Message(std::string_view line) override {
    if (inner_) inner_->Message(line);
  }
  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (inner_) inner_->Progress(done, total, voxels);
  }
  void Done() override {
    if (inner_) inner_->Done();
  }
  bool Cancelled() override { return cancel_->load() || (inner_ && inner_->Cancelled()); }

 private:
  vox::ProgressSink* inner_;
  const std::atomic<bool>* cancel_;
};

class PythonProgress : public vox::ProgressSink {
 public:
  explicit PythonProgress(py::object fn) : fn_(std::move(fn)) {}
  ~PythonProgress() override {
    py::gil_scoped_acquire gil;
    fn_ = py::object();
  }
  void Message(std::string_view) override {}
  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (error_) return;
    py::gil_scoped_acquire gil;
    try {
      fn_(done, total, voxels);
    } catch (py::error_already_set& e) {
      error_ = std::make_unique<py::error_already_set>(std::move(e));
      failed_ = true;
    }
  }
  void Done() override {}
  // A callback that raised stops the ingest; its exception is raised.
  bool Cancelled() override { return failed_.load(); }
  void Rethrow() {
    if (error_) {
      error_->restore();
      error_.reset();
      throw py::error_already_set();
    }
  }

 private:
  std::mutex mu_;
  py::object fn_;
  std::unique_ptr<py::error_already_set> error_;
  std::atomic<bool> failed_{false};
};

py::dict Ingest(const py::object& vdb, const py::object& store, const py::object& progress,
                const py::kwargs& kwargs) {
  vox::IngestCommand c;
  c.quiet = true;  // Python: no stderr output unless quiet=False
  if (kwargs.contains("quiet") && !kwargs["quiet"].is_none())
    c.quiet = QuietKwarg("ingest", kwargs["quiet"]);
  py::kwargs rest;
  for (const auto& [k, v] : kwargs)
    if (py::str(k).cast<std::string>() != "quiet") rest[k] = v;
  c.options.input = PathOf(vdb);
  c.options.output = PathOf(store);
  // Recorded in the store's build_options, as the tool records its command line.
  std::string line = "vox.ingest " + c.options.input + " " + c.options.output;
  std::vector<std::string> flags;  // for the child process: the same flags
  ApplyKwargs(rest, "ingest", vox::IngestOptionTable(), [&](const std::string& f, const std::string& v) {
    line += " " + f;
    flags.push_back(f);
    if (vox::ArityOf(vox::IngestOptionTable(), f) == vox::FlagArity::kValue) {
      line += " " + v;
      flags.push_back(v);
    }
    return vox::ApplyIngestFlag(&c, f, v);
  });
  c.options.command_line = line;
  if (!c.add_lod.empty())
    throw py::type_error("ingest(): add_lod is vox-ingest --add-lod STORE; not available here");
  CheckUsage(vox::CheckIngestCommand(c));
  std::unique_ptr<PythonProgress> py_progress;
  std::unique_ptr<vox::ProgressSink> stderr_progress;
  vox::ProgressSink* sink = nullptr;
  if (!progress.is_none()) {
    py_progress = std::make_unique<PythonProgress>(progress);
    sink = py_progress.get();
  } else if (!c.quiet) {
    stderr_progress = vox::MakeStderrProgress(false);
    sink = stderr_progress.get();
  }
  std::atomic<bool> cancel{false};
  CancelSink cancel_sink(sink, &cancel);
  // The ingest runs in a child interpreter (tools/python/ingest_process.h),
  // as vox-ingest's runs in a child: a crash there raises here.
  const py::module_ sys = py::module_::import("sys");
  const std::string python = py::str(sys.attr("executable"));
  if (python.empty())
    throw std::runtime_error("ingest(): sys.executable is empty: no interpreter to run the "
                             "ingest's child process in");
  const std::vector<std::string> argv = {
      python, "-c",
      "import importlib, sys; sys.exit(importlib.import_module(sys.argv[1])._ingest_child("
      "sys.argv[2:]))",
      g_module_name};
  std::string path;  // the child imports the module from where this one came
  for (const py::handle& entry : sys.attr("path")) {
    const std::string e = py::str(entry);
    if (!e.empty()) path += (path.empty() ? "" : ":") + e;
  }
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e)
    if (std::strncmp(*e, "PYTHONPATH=", 11) != 0) env.emplace_back(*e);
  env.push_back("PYTHONPATH=" + path);
  const vox::IngestChildRequest request{c.options.input, c.options.output, line, flags};
  std::optional<vox::StatusOr<std::string>> result;
  RunPolled(&cancel, [&] {
    result.emplace(vox::RunIngestChildProcess(argv, env, request, &cancel_sink, &cancel));
  });
  if (py_progress) py_progress->Rethrow();
  CheckRun(result->status());
  return JsonToPython(**result);
}

// The child process of vox.ingest: the module's private entry point.
int IngestChild(const std::vector<std::string>& args) {
  py::gil_scoped_release release;
  return vox::RunIngestChild(args);
}

// --- Store ------------------------------------------------------------------

py::list Vec3(const glm::i64vec3& v) { return py::cast(std::vector<int64_t>{v.x, v.y, v.z}); }

// vox-info's report as a dict: the same quantities, in bytes and counts.
py::dict InfoDict(const vox::StoreInfo& i) {
  const vox::StoreMeta& m = i.meta;
  py::dict d;
  d["dir"] = i.dir;
  d["format"] = std::to_string(i.format_major) + "." + std::to_string(i.format_minor);
  d["source"] = m.source_file;
  d["grid"] = m.grid_name;
  d["grid_class"] = m.grid_class == vox::GridClass::kLevelSet ? "level set" : "fog volume";
  if (m.grid_class == vox::GridClass::kLevelSet)
    d["isovalue"] = m.isovalue;
  else
    d["threshold"] = m.threshold;
  py::list attrs;
  if (m.has_normal) attrs.append("normal");
  if (m.has_density) attrs.append("density");
  if (m.has_color) attrs.append("colour");
  if (m.has_temperature) attrs.append("temperature");
  d["attributes"] = attrs;
  d["build_options"] = m.build_options;
  d["bbox_min"] = Vec3(m.bbox_min);
  d["bbox_max"] = Vec3(m.bbox_max);
  d["bbox_dimensions"] = Vec3(m.voxel_count ? m.bbox_max - m.bbox_min + glm::i64vec3(1)
                                            : glm::i64vec3(0));
  d["origin"] = Vec3(m.origin);
  d["voxel_size"] = m.voxel_size;
  py::list rows;  // index -> world, row-major 3x4 as vox-info prints it
  for (int r = 0; r < 3; ++r)
    rows.append(py::cast(std::vector<double>{m.index_to_world[0][r], m.index_to_world[1][r],
                                             m.index_to_world[2][r], m.index_to_world[3][r]}));
  d["index_to_world"] = rows;
  d["levels"] = m.levels;
  d["brick_level"] = m.brick_level;
  d["voxels"] = m.voxel_count;
  d["cells"] = m.top_cells + i.brick_cells;
  d["top_cells"] = m.top_cells;
  d["brick_cells"] = i.brick_cells;
  d["bricks"] = m.brick_count;
  d["brick_voxels"] = py::dict(
      py::arg("min") = i.min_brick_voxels,
      py::arg("mean") = m.brick_count ? double(m.voxel_count) / double(m.brick_count) : 0.0,
      py::arg("max") = i.max_brick_voxels);
  d["index_file_bytes"] = i.index_file_bytes;
  d["brick_file_bytes"] = i.brick_file_bytes;
  d["top_bytes"] = i.top_bytes;
  d["resident_bytes"] = i.resident_bytes;
  d["stored_bytes"] = i.stored_bytes;
  d["raw_bytes"] = i.raw_bytes;
  d["decoded_bytes"] = i.decoded_bytes;
  py::dict hist;  // [2^k, 2^(k+1)) bytes -> bricks
  for (size_t k = 0; k < i.stored_size_histogram.size(); ++k)
    if (i.stored_size_histogram[k]) hist[py::int_(uint64_t(1) << k)] = i.stored_size_histogram[k];
  d["stored_size_histogram"] = hist;
  d["verified"] = i.verified;
  return d;
}

class PyStore {
 public:
  explicit PyStore(const py::object& path) : path_(PathOf(path)) {
    std::optional<vox::StatusOr<vox::StoreInfo>> info;
    {
      py::gil_scoped_release release;
      info.emplace(vox::InspectStore(path_, false));
    }
    CheckRun(info->status());
    info_ = **info;
  }
  const std::string& path() const { return path_; }
  py::dict info() const { return InfoDict(info_); }
  std::string report() const { return vox::FormatStoreInfo(info_); }

 private:
  std::string path_;
  vox::StoreInfo info_;
};

// --- render -----------------------------------------------------------------

py::dict Render(const py::object& store, const py::object& camera, const py::object& scene,
                const py::kwargs& kwargs) {
  vox::RenderJobOptions o;
  o.store_dir = PathOf(store);
  o.exr_path.clear();  // no EXR unless o="out.exr"
  o.quiet = true;      // no stderr output unless quiet=False
  o.keep_image = true;
  auto dumps = py::module_::import("json").attr("dumps");
  if (py::isinstance<py::dict>(camera) || py::isinstance<py::list>(camera))  // a list: a sequence
    o.camera_json = dumps(camera).cast<std::string>();
  else if (!camera.is_none())
    o.camera_path = PathOf(camera);
  if (py::isinstance<py::dict>(scene))
    o.scene_json = dumps(scene).cast<std::string>();
  else if (!scene.is_none())
    o.scene_path = PathOf(scene);
  py::kwargs rest;
  for (const auto& [k, v] : kwargs) {
    if (py::str(k).cast<std::string>() == "quiet" && !v.is_none())
      o.quiet = QuietKwarg("render", v);
    else
      rest[k] = v;
  }
  ApplyKwargs(rest, "render", vox::RenderOptionTable(),
              [&](const std::string& f, const std::string& v) { return vox::ApplyRenderFlag(&o, f, v); });
  std::atomic<bool> cancel{false};
  o.interrupted = [&cancel]() -> vox::Status {
    return cancel.load() ? vox::UnavailableError("render cancelled") : vox::OkStatus();
  };
  vox::RenderJobOutput out;
  vox::Status s;
  RunPolled(&cancel, [&] { s = vox::RunRenderJob(o, &out); });
  CheckRun(s);
  const py::ssize_t h = out.height, w = out.width;
  py::dict d;
  d["rgba"] = Owned(std::move(out.rgba), {h, w, 4});
  d["z"] = Owned(std::move(out.z), {h, w});
  if (o.layers.normal) d["normal"] = Owned(std::move(out.normal), {h, w, 3});
  if (o.layers.voxel) d["voxel"] = Owned(std::move(out.voxel), {h, w, 3});
  if (o.layers.position) d["position"] = Owned(std::move(out.position), {h, w, 3});
  if (o.layers.distance) d["distance"] = Owned(std::move(out.distance), {h, w});
  d["stats"] = JsonToPython(out.stats_json);
  return d;
}

// --- probe ------------------------------------------------------------------

py::tuple Probe(const py::object& store, const py::object& rays_in, const py::kwargs& kwargs) {
  vox::ProbeOptions opt;
  if (!store.is_none()) opt.store = PathOf(store);
  ApplyKwargs(kwargs, "probe", vox::ProbeOptionTable(),
              [&](const std::string& f, const std::string& v) { return vox::ApplyProbeFlag(&opt, f, v); });
  auto rays = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(rays_in);
  if (!rays || rays.ndim() != 2 || rays.shape(1) != 6)
    throw py::value_error("rays must be an (N, 6) array (ox oy oz dx dy dz per row, index space)");
  const py::ssize_t n = rays.shape(0);
  std::vector<int64_t> voxels(size_t(n) * 3, 0);
  std::vector<double> t(size_t(n), std::numeric_limits<double>::infinity());
  std::vector<uint8_t> hit(size_t(n), 0);
  std::unique_ptr<vox::Prober> prober;
  vox::Status status;
  py::ssize_t bad_row = -1;
  vox::TraceCounters counters;
  std::atomic<bool> cancel{false};  // Ctrl-C: checked every ray
  RunPolled(&cancel, [&] {
    auto opened = vox::Prober::Open(opt);
    status = opened.status();
    if (!status.ok()) return;
    prober = std::move(opened).value();
    const double* r = rays.data();
    for (py::ssize_t i = 0; i < n && !cancel.load(std::memory_order_relaxed); ++i) {
      vox::Ray ray;
      ray.origin = {r[i * 6 + 0], r[i * 6 + 1], r[i * 6 + 2]};
      ray.dir = {r[i * 6 + 3], r[i * 6 + 4], r[i * 6 + 5]};
      auto h = prober->Trace(ray, &counters);
      if (!h.ok()) {
        status = h.status();
        bad_row = i;
        return;
      }
      if (*h) {
        const vox::Hit& x = **h;
        for (int c = 0; c < 3; ++c) voxels[size_t(i) * 3 + c] = x.voxel[c];
        t[size_t(i)] = x.t;
        hit[size_t(i)] = 1;
      }
    }
  });
  if (bad_row >= 0) Raise(status.code(), "rays[" + std::to_string(bad_row) + "]: " + status.message());
  if (!status.ok()) Raise(status.code(), status.message());  // as vox-probe prints it
  if (opt.stats) py::print("vox-probe:", counters.ToString(), py::arg("file") = py::module_::import("sys").attr("stderr"));
  auto hit_array = Owned(std::move(hit), {n}).attr("astype")("bool");
  return py::make_tuple(Owned(std::move(voxels), {n, 3}), Owned(std::move(t), {n}), hit_array);
}

// --- EXR --------------------------------------------------------------------

py::dict ReadExr(const py::object& path) {
  const std::string p = PathOf(path);
  std::optional<vox::StatusOr<vox::ExrImage>> img;
  {
    py::gil_scoped_release release;
    img.emplace(vox::ReadExr(p));
  }
  CheckRun(img->status());
  vox::ExrImage& im = **img;
  py::dict channels;
  for (auto& [name, v] : im.pixels)
    channels[py::str(name)] = Owned(std::move(v), {im.info.height, im.info.width});
  py::dict d;
  d["width"] = im.info.width;
  d["height"] = im.info.height;
  d["channels"] = channels;
  d["attributes"] = im.info.attrs;
  return d;
}

}  // namespace

PYBIND11_MODULE(_vox, m) {
  g_module_name = py::str(m.attr("__name__"));
  m.doc() =
      "vox: out-of-core discrete ray tracing of huge sparse voxel volumes (ingest OpenVDB, "
      "render, probe). Options are the command-line tools' flags as keyword arguments.";
  m.def("_ingest_child", &IngestChild, py::arg("args"),
        "vox.ingest's child process (tools/python/ingest_process.h); not for direct use.");
  m.def("ingest", &Ingest, py::arg("vdb_path"), py::arg("store_path"),
        py::arg("progress") = py::none(),
        "Ingests an OpenVDB grid into a vox store, as vox-ingest; options are its flags "
        "(grid, levels, isovalue, threshold, color, temperature, source, zstd_level, normal_bits, "
        "threads, memory_mb, force, quiet). progress(bricks_done, bricks_total, voxels_done) is called as bricks are "
        "written. Returns the ingest's statistics.");
  py::class_<PyStore>(m, "Store", "A vox store: its metadata as vox-info prints it.")
      .def(py::init<const py::object&>(), py::arg("path"))
      .def_property_readonly("path", &PyStore::path)
      .def_property_readonly("info", &PyStore::info, "vox-info's metadata and statistics")
      .def("__str__", &PyStore::report)
      .def("__repr__", [](const PyStore& s) { return "vox.Store('" + s.path() + "')"; });
  m.def("render", &Render, py::arg("store"), py::arg("camera") = py::none(),
        py::arg("scene") = py::none(),
        "Renders a store as vox-render. camera and scene are dicts in the cam.json and "
        "scene.json schema, or paths; options are vox-render's flags (split, single_step, "
        "memory_mb, cache_mb, threads, tile_size, tiles, layers, size, view, save_cam, prefetch, "
        "o, preview, stats, quiet, turntable, frames); size=(W, H) overrides the camera's. "
        "A list of cameras or turntable=N is a sequence, of which frames=K renders frame K (one "
        "frame per call; vox-render renders whole sequences). Returns {'rgba': (H, W, 4) float32 (premultiplied), 'z': (H, W) planar "
        "depth, 'normal', 'voxel' and 'position': (H, W, 3) and 'distance': (H, W) when layers "
        "asks for them, 'stats': the --stats document}; docs/usage.md has the layout.");
  m.def("probe", &Probe, py::arg("store"), py::arg("rays"),
        "First hits of index-space rays, as vox-probe: rays is (N, 6) (ox oy oz dx dy dz). "
        "store is a store path, or None with generate='sphere:64'; options are vox-probe's "
        "flags (split, single_step, memory_mb, cache_mb, fixed, tracer, generate, brick_level, "
        "stats); tracer='render' (default) answers as vox-render traces, tracer='long-double' "
        "with a long-double set-up. "
        "Returns (voxels (N, 3) int64, t (N,) float64, hit (N,) bool); misses have t = inf.");
  m.def("read_exr", &ReadExr, py::arg("path"),
        "Reads a complete EXR written by vox: {'width', 'height', 'channels': {name: (H, W) "
        "float32}, 'attributes': the string attributes}.");
  voxpy::RegisterValues(m);
  m.attr("__version__") = vox::kVersion;
  m.attr("__git_describe__") = vox::kGitDescribe;
}

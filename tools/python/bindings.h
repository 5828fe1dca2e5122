// Shared by the Python module's binding files (module.cpp, values.cpp):
// Status -> Python exceptions, paths, and numpy arrays that own a vector.
#ifndef VOX_TOOLS_PYTHON_BINDINGS_H_
#define VOX_TOOLS_PYTHON_BINDINGS_H_

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <vector>

#include "core/util/status.h"

namespace voxpy {

namespace py = pybind11;

[[noreturn]] inline void Raise(vox::StatusCode code, const std::string& text) {
  PyObject* type = PyExc_RuntimeError;
  switch (code) {
    case vox::StatusCode::kInvalidArgument:
    case vox::StatusCode::kUnsupported:
      type = PyExc_ValueError;
      break;
    case vox::StatusCode::kNotFound:
    case vox::StatusCode::kIoError:
    case vox::StatusCode::kCorruption:
      type = PyExc_OSError;
      break;
    default:
      break;
  }
  PyErr_SetString(type, text.c_str());
  throw py::error_already_set();
}

// A refused option: the tool prints the message alone.
inline void CheckUsage(const vox::Status& s) {
  if (!s.ok()) Raise(s.code(), s.message());
}
// A failed run: the tool prints "Code: message".
inline void CheckRun(const vox::Status& s) {
  if (!s.ok()) Raise(s.code(), s.ToString());
}

// str, bytes, os.PathLike or vox.Store -> a path: its bytes in the file
// system's encoding (os.fsencode; bytes as they are), the file Python names.
inline std::string PathOf(const py::handle& h) {
  if (py::hasattr(h, "path") && !py::isinstance<py::str>(h) && !py::isinstance<py::bytes>(h))
    return PathOf(h.attr("path"));
  return py::module_::import("os").attr("fsencode")(h).cast<std::string>();
}

template <class T>
py::array_t<T> Owned(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* heap = new std::vector<T>(std::move(v));
  py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, heap->data(), owner);
}

// vox.sample, vox.read, vox.slice, vox.ingest_array (values.cpp).
void RegisterValues(py::module_& m);

}  // namespace voxpy

#endif  // VOX_TOOLS_PYTHON_BINDINGS_H_

// A dense array (numpy's memory, a .npy file, a raw file) as a fog volume:
// element [i, j, k] becomes voxel (i, j, k) + origin (index units), occupied
// with its value as the density where the value exceeds `threshold`, in a
// grid named "density" whose index-to-world map is a uniform scale by
// voxel_size.
//
// vox::IngestArray writes the store straight from the array, brick by brick
// (array_stream.cpp): no grid and no temporary file, and the memory held is
// the writer's and the pyramid's whatever the array's size (a mapped file's
// pages are read as the bricks need them and belong to the page cache). The
// store is the one vox::Ingest makes of the same array written as a .vdb by
// vox::ArrayToVdb (the same metadata and bricks; the store id, its source and
// build options aside).
//
// vox::ArrayToVdb writes the array as an OpenVDB fog volume (the Python
// module's vox.ingest_array, and the tests' second way to the same store);
// it holds the grid in memory, about 4 bytes per voxel of every leaf that
// holds an element above the threshold.
//
// Thread safety: the functions may be called from any thread.
#ifndef VOX_INGEST_ARRAY_INGEST_H_
#define VOX_INGEST_ARRAY_INGEST_H_

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "core/util/status.h"
#include "ingest/ingest.h"

namespace vox {

// An array's elements in memory: dtype in numpy's notation ("<f4", "|u1",
// "float32", "uint16", ...: little-endian floats and integers of 1 to 8
// bytes), C order (x slowest) unless fortran_order.
struct ArrayView {
  std::string dtype;
  std::array<int64_t, 3> shape{0, 0, 0};
  bool fortran_order = false;
  const void* data = nullptr;
};

struct ArrayPlacement {
  double voxel_size = 1.0;
  std::array<int64_t, 3> origin{0, 0, 0};
  double threshold = 0.0;
};

// A file mapped into memory, its array described by `view`.
class MappedArray {
 public:
  ~MappedArray();
  const ArrayView& view() const { return view_; }

  // A .npy file (format 1.0 to 3.0, a 3-D array of a supported dtype).
  static StatusOr<std::unique_ptr<MappedArray>> OpenNpy(const std::string& path);
  // A raw file of shape[0] * shape[1] * shape[2] elements of `dtype`, C order.
  static StatusOr<std::unique_ptr<MappedArray>> OpenRaw(const std::string& path,
                                                        const std::array<int64_t, 3>& shape,
                                                        const std::string& dtype);

 private:
  MappedArray() = default;
  void* base_ = nullptr;
  size_t length_ = 0;
  ArrayView view_;
};

// The element size of a dtype, or InvalidArgument naming the supported ones.
StatusOr<int> DtypeSize(const std::string& dtype);

// Writes the array as a fog volume to a new .vdb file at `vdb_path`.
// `what` names the input in errors (a file, "the array").
Status ArrayToVdb(const ArrayView& array, const ArrayPlacement& placement, const std::string& vdb_path,
                  const std::string& what);

// Ingests the array into a store at options.output (ingest.h's contract: a
// failed ingest leaves no store, an existing one is replaced only with
// options.force). options.input names the array in messages and, unless
// options.source is set, as the store's source. The array's threshold is
// placement.threshold (options.threshold, when set, must equal it);
// options.grid_name, color_grid, temperature_grid and isovalue are refused.
StatusOr<IngestStats> IngestArray(const ArrayView& array, const ArrayPlacement& placement,
                                  const IngestOptions& options, ProgressSink* progress = nullptr);
// The same with another writer (tests).
StatusOr<IngestStats> IngestArrayWithWriter(const ArrayView& array,
                                            const ArrayPlacement& placement,
                                            const IngestOptions& options,
                                            const WriterFactory& factory,
                                            ProgressSink* progress = nullptr);

}  // namespace vox

#endif  // VOX_INGEST_ARRAY_INGEST_H_

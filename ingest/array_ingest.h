// vox::ArrayToVdb: a dense array (numpy's memory, a .npy file, a raw file)
// as an OpenVDB fog volume, so that it is ingested (ingest.h) exactly as a
// .vdb holding the same grid would be: element [i, j, k] becomes voxel
// (i, j, k) + origin (index units), active with its value as the density
// where the value exceeds `threshold`, in a grid named "density" whose
// index-to-world map is a uniform scale by voxel_size.
//
// Files are mapped (mmap), not read whole: the pages of the input are read
// as the grid is built, a slab of x at a time, and the memory held is the
// grid's, about 4 bytes per voxel above the threshold (plus its leaves'
// inactive voxels) and none for the rest of the array.
//
// Thread safety: the functions may be called from any thread.
#ifndef VOX_INGEST_ARRAY_INGEST_H_
#define VOX_INGEST_ARRAY_INGEST_H_

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "core/util/status.h"

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

}  // namespace vox

#endif  // VOX_INGEST_ARRAY_INGEST_H_

#include "ingest/array_ingest.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <exception>
#include <regex>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include "ingest/internal/array_values.h"

namespace vox {

using ingest_internal::CanonicalDtype;
using ingest_internal::CheckArrayPlacement;
using ingest_internal::CheckArrayShape;
using ingest_internal::ElementIndex;
using ingest_internal::ElementLoader;
using ingest_internal::LoaderOf;

StatusOr<int> DtypeSize(const std::string& dtype) {
  VOX_ASSIGN_OR_RETURN(std::string code, CanonicalDtype(dtype));
  return code[1] - '0';
}

MappedArray::~MappedArray() {
  if (base_ != nullptr) ::munmap(base_, length_);
}

namespace {
StatusOr<std::unique_ptr<MappedArray>> Map(const std::string& path, size_t* length, void** base) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return IoError("cannot open '" + path + "': " + std::strerror(errno));
  struct stat st;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return InvalidArgumentError("'" + path + "' is not a regular file");
  }
  *length = size_t(st.st_size);
  *base = *length ? ::mmap(nullptr, *length, PROT_READ, MAP_PRIVATE, fd, 0) : nullptr;
  ::close(fd);
  if (*base == MAP_FAILED) {
    *base = nullptr;
    return IoError("cannot map '" + path + "': " + std::strerror(errno));
  }
  if (*base) ::madvise(*base, *length, MADV_SEQUENTIAL);
  return std::unique_ptr<MappedArray>();
}
}  // namespace

StatusOr<std::unique_ptr<MappedArray>> MappedArray::OpenRaw(const std::string& path,
                                                            const std::array<int64_t, 3>& shape,
                                                            const std::string& dtype) {
  VOX_RETURN_IF_ERROR(CheckArrayShape(shape, "'" + path + "'"));
  VOX_ASSIGN_OR_RETURN(int size, DtypeSize(dtype));
  std::unique_ptr<MappedArray> m(new MappedArray());
  VOX_RETURN_IF_ERROR(Map(path, &m->length_, &m->base_).status());
  const double want = double(shape[0]) * double(shape[1]) * double(shape[2]) * size;
  if (double(m->length_) != want)
    return InvalidArgumentError("'" + path + "' has " + std::to_string(m->length_) + " bytes; shape " +
                                std::to_string(shape[0]) + " x " + std::to_string(shape[1]) + " x " +
                                std::to_string(shape[2]) + " of " + dtype + " needs " +
                                std::to_string(uint64_t(want)));
  m->view_ = ArrayView{dtype, shape, false, m->base_};
  return m;
}

StatusOr<std::unique_ptr<MappedArray>> MappedArray::OpenNpy(const std::string& path) {
  std::unique_ptr<MappedArray> m(new MappedArray());
  VOX_RETURN_IF_ERROR(Map(path, &m->length_, &m->base_).status());
  const char* p = static_cast<const char*>(m->base_);
  const auto bad = [&](const std::string& why) {
    return InvalidArgumentError("'" + path + "' is not a .npy file vox reads: " + why);
  };
  if (m->length_ < 10 || std::memcmp(p, "\x93NUMPY", 6) != 0) return bad("no .npy magic");
  const int major = (unsigned char)p[6];
  size_t header_len = 0, start = 0;
  if (major == 1) {
    header_len = size_t((unsigned char)p[8]) | size_t((unsigned char)p[9]) << 8;
    start = 10;
  } else if (major == 2 || major == 3) {
    if (m->length_ < 12) return bad("truncated header");
    for (int i = 0; i < 4; ++i) header_len |= size_t((unsigned char)p[8 + i]) << (8 * i);
    start = 12;
  } else {
    return bad("format version " + std::to_string(major));
  }
  if (start + header_len > m->length_) return bad("truncated header");
  const std::string header(p + start, header_len);
  std::smatch descr, fortran, shape;
  static const std::regex kDescr("'descr'\\s*:\\s*'([^']*)'"), kFortran("'fortran_order'\\s*:\\s*(True|False)"),
      kShape("'shape'\\s*:\\s*\\(\\s*(\\d+)\\s*,\\s*(\\d+)\\s*,\\s*(\\d+)\\s*,?\\s*\\)");
  if (!std::regex_search(header, descr, kDescr)) return bad("no descr in the header");
  if (!std::regex_search(header, fortran, kFortran)) return bad("no fortran_order in the header");
  if (!std::regex_search(header, shape, kShape)) return bad("the array is not 3-D");
  ArrayView v;
  v.dtype = descr[1];
  v.fortran_order = fortran[1] == "True";
  for (int a = 0; a < 3; ++a) v.shape[size_t(a)] = std::stoll(shape[a + 1]);
  VOX_RETURN_IF_ERROR(CheckArrayShape(v.shape, "'" + path + "'"));
  auto size = DtypeSize(v.dtype);
  if (!size.ok()) return bad(size.status().message());
  const size_t offset = start + header_len;
  const double want = double(v.shape[0]) * double(v.shape[1]) * double(v.shape[2]) * *size;
  if (double(m->length_ - offset) != want)
    return bad("its data is " + std::to_string(m->length_ - offset) + " bytes, its header says " +
               std::to_string(uint64_t(want)));
  v.data = p + offset;
  m->view_ = v;
  return m;
}

Status ArrayToVdb(const ArrayView& a, const ArrayPlacement& place, const std::string& vdb_path,
                  const std::string& what) {
  VOX_RETURN_IF_ERROR(CheckArrayShape(a.shape, what));
  auto code = CanonicalDtype(a.dtype);
  if (!code.ok()) return InvalidArgumentError(what + ": " + code.status().message());
  VOX_RETURN_IF_ERROR(CheckArrayPlacement(a, place, what));
  const ElementLoader load = LoaderOf(*code);
  try {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(place.voxel_size));
    auto acc = grid->getAccessor();
    const int64_t nx = a.shape[0], ny = a.shape[1], nz = a.shape[2];
    const float threshold = float(place.threshold);
    for (int64_t i = 0; i < nx; ++i)
      for (int64_t j = 0; j < ny; ++j)
        for (int64_t k = 0; k < nz; ++k) {
          const float v = load(a.data, ElementIndex(a, i, j, k));
          if (!(v > threshold)) continue;
          acc.setValue(openvdb::Coord(int(i + place.origin[0]), int(j + place.origin[1]), int(k + place.origin[2])), v);
        }
    openvdb::io::File(vdb_path).write({grid});
  } catch (const std::exception& e) {
    ::unlink(vdb_path.c_str());
    return IoError(what + ": cannot write the grid to '" + vdb_path + "': " + e.what());
  }
  return OkStatus();
}

}  // namespace vox

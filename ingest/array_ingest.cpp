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

namespace vox {

namespace {

// numpy's names and descr strings -> a canonical "f4", "u1", "i2", ...
StatusOr<std::string> Canonical(const std::string& dtype) {
  static const std::pair<const char*, const char*> kNames[] = {
      {"float32", "f4"}, {"float64", "f8"}, {"uint8", "u1"}, {"uint16", "u2"}, {"uint32", "u4"},
      {"uint64", "u8"}, {"int8", "i1"}, {"int16", "i2"}, {"int32", "i4"}, {"int64", "i8"},
      {"float", "f4"}, {"double", "f8"}};
  for (auto& [name, code] : kNames)
    if (dtype == name) return std::string(code);
  std::string d = dtype;
  if (!d.empty() && (d[0] == '<' || d[0] == '|' || d[0] == '=')) d = d.substr(1);
  static const char* kCodes[] = {"f4", "f8", "u1", "u2", "u4", "u8", "i1", "i2", "i4", "i8"};
  for (const char* c : kCodes)
    if (d == c) return d;
  return InvalidArgumentError("dtype '" + dtype +
                              "' is not supported: give float32, float64, (u)int8, (u)int16, "
                              "(u)int32 or (u)int64, little-endian");
}

template <class T>
float Load(const void* base, size_t index) {
  T v;
  std::memcpy(&v, static_cast<const char*>(base) + index * sizeof(T), sizeof(T));
  return float(v);
}

using Loader = float (*)(const void*, size_t);

Loader LoaderOf(const std::string& code) {
  if (code == "f4") return Load<float>;
  if (code == "f8") return Load<double>;
  if (code == "u1") return Load<uint8_t>;
  if (code == "u2") return Load<uint16_t>;
  if (code == "u4") return Load<uint32_t>;
  if (code == "u8") return Load<uint64_t>;
  if (code == "i1") return Load<int8_t>;
  if (code == "i2") return Load<int16_t>;
  if (code == "i4") return Load<int32_t>;
  return Load<int64_t>;
}

Status CheckShape(const std::array<int64_t, 3>& s, const std::string& what) {
  for (int a = 0; a < 3; ++a)
    if (s[size_t(a)] <= 0 || s[size_t(a)] > (int64_t(1) << 31))
      return InvalidArgumentError(what + ": shape " + std::to_string(s[0]) + " x " + std::to_string(s[1]) +
                                  " x " + std::to_string(s[2]) + " is not 3 positive sizes below 2^31");
  return OkStatus();
}

}  // namespace

StatusOr<int> DtypeSize(const std::string& dtype) {
  VOX_ASSIGN_OR_RETURN(std::string code, Canonical(dtype));
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
  VOX_RETURN_IF_ERROR(CheckShape(shape, "'" + path + "'"));
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
  VOX_RETURN_IF_ERROR(CheckShape(v.shape, "'" + path + "'"));
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
  VOX_RETURN_IF_ERROR(CheckShape(a.shape, what));
  auto code = Canonical(a.dtype);
  if (!code.ok()) return InvalidArgumentError(what + ": " + code.status().message());
  if (!(place.voxel_size > 0) || !std::isfinite(place.voxel_size))
    return InvalidArgumentError(what + ": voxel_size must be positive");
  if (!std::isfinite(place.threshold)) return InvalidArgumentError(what + ": threshold must be finite");
  for (int c = 0; c < 3; ++c)
    if (std::llabs(place.origin[size_t(c)]) + a.shape[size_t(c)] > (int64_t(1) << 30))
      return InvalidArgumentError(what + ": origin + shape leaves OpenVDB's index range");
  const Loader load = LoaderOf(*code);
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
          const size_t index = a.fortran_order ? size_t((k * ny + j) * nx + i) : size_t((i * ny + j) * nz + k);
          const float v = load(a.data, index);
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

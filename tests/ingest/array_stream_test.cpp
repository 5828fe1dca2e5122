// IngestArray (the array straight into a store, brick by brick) against the
// other way to the same store: the array written as a .vdb fog volume by
// ArrayToVdb and ingested by vox::Ingest. Both stores must be the same (the
// metadata but for the store id, source and build options; every voxel with
// its brick, payload and density; the pyramid's levels likewise), and the
// voxels the elements above the threshold, counted here from the array.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "ingest/array_ingest.h"
#include "storage/lod.h"
#include "storage/store.h"
#include "tests/ingest/ingest_test_util.h"
#include "tests/ingest/same_store.h"

namespace vox {
namespace {

using testutil::Ijk;

struct TestArray {
  std::vector<char> bytes;
  ArrayView view;
};

// Elements of `dtype` (T) of `shape`, from `value(i, j, k)`, laid out in C or
// Fortran order.
template <class T, class F>
TestArray MakeArray(const std::string& dtype, std::array<int64_t, 3> shape, bool fortran, F value) {
  TestArray a;
  a.bytes.resize(size_t(shape[0] * shape[1] * shape[2]) * sizeof(T));
  for (int64_t i = 0; i < shape[0]; ++i)
    for (int64_t j = 0; j < shape[1]; ++j)
      for (int64_t k = 0; k < shape[2]; ++k) {
        const size_t n = fortran ? size_t((k * shape[1] + j) * shape[0] + i)
                                 : size_t((i * shape[1] + j) * shape[2] + k);
        const T v = T(value(i, j, k));
        std::memcpy(a.bytes.data() + n * sizeof(T), &v, sizeof(T));
      }
  a.view = ArrayView{dtype, shape, fortran, a.bytes.data()};
  return a;
}

class ArrayStreamTest : public ::testing::Test {
 protected:
  // Ingests `a` both ways; expects the same store and pyramid, whose base
  // holds `expected` voxels.
  void Check(const TestArray& a, const ArrayPlacement& place, uint64_t expected) {
    const std::string vdb = dir_.File("a.vdb"), via = dir_.File("via_vdb"),
                      direct = dir_.File("direct");
    std::filesystem::remove_all(via);
    std::filesystem::remove_all(direct);
    ASSERT_TRUE(ArrayToVdb(a.view, place, vdb, "the array").ok());
    IngestOptions o;
    o.input = vdb;
    o.output = via;
    o.threshold = place.threshold;
    o.threads = 2;
    auto s1 = Ingest(o);
    ASSERT_TRUE(s1.ok()) << s1.status().ToString();
    o.input = "the array";
    o.output = direct;
    auto s2 = IngestArray(a.view, place, o);
    ASSERT_TRUE(s2.ok()) << s2.status().ToString();
    EXPECT_EQ(s2->occupied_voxels, expected);
    EXPECT_EQ(s1->occupied_voxels, s2->occupied_voxels);
    EXPECT_EQ(s1->bricks, s2->bricks);
    EXPECT_EQ(testutil::ExpectSameStoreAndPyramid(via, direct), expected);
  }
  testutil::TempDir dir_;
};

template <class T>
uint64_t CountAbove(const TestArray& a, double threshold) {
  uint64_t n = 0;
  for (size_t e = 0; e < a.bytes.size() / sizeof(T); ++e) {
    T v;
    std::memcpy(&v, a.bytes.data() + e * sizeof(T), sizeof(T));
    n += float(v) > float(threshold);
  }
  return n;
}

TEST_F(ArrayStreamTest, Float32CorderAcrossBricks) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const TestArray a = MakeArray<float>("<f4", {70, 45, 33}, false, [&](auto...) { return u(rng); });
  ArrayPlacement place;
  place.voxel_size = 0.25;
  place.origin = {-40, 3, 100};
  place.threshold = 0.6;
  Check(a, place, CountAbove<float>(a, 0.6));
}

TEST_F(ArrayStreamTest, Uint8FortranOrder) {
  const TestArray a = MakeArray<uint8_t>(
      "|u1", {40, 50, 36}, true,
      [](int64_t i, int64_t j, int64_t k) { return (i * 7 + j * 13 + k * 29) % 256; });
  ArrayPlacement place;
  place.origin = {5, -7, 0};
  place.threshold = 100;
  Check(a, place, CountAbove<uint8_t>(a, 100));
}

TEST_F(ArrayStreamTest, Float64BallWithNegativeThresholdAndEmptyBricks) {
  // A ball at one end and one voxel at the other: bricks between are empty.
  const TestArray a =
      MakeArray<double>("<f8", {150, 20, 20}, false, [](int64_t i, int64_t j, int64_t k) {
        if (i == 149 && j == 19 && k == 0) return 2.5;
        const double r2 = double((i - 9) * (i - 9) + (j - 9) * (j - 9) + (k - 9) * (k - 9));
        return r2 < 64 ? 1.0 - r2 / 64 : -1.0;
      });
  ArrayPlacement place;
  place.threshold = -0.5;
  Check(a, place, CountAbove<double>(a, -0.5));
}

TEST_F(ArrayStreamTest, Int16SmallerThanABrick) {
  const TestArray a = MakeArray<int16_t>(
      "int16", {3, 4, 5}, false,
      [](int64_t i, int64_t j, int64_t k) { return int16_t(i * 100 - j * 50 + k); });
  ArrayPlacement place;
  place.origin = {1000, 0, -1000};
  Check(a, place, CountAbove<int16_t>(a, 0));
}

TEST_F(ArrayStreamTest, NothingAboveTheThresholdIsAnEmptyStore) {
  const TestArray a =
      MakeArray<float>("float32", {10, 10, 10}, false, [](auto...) { return 0.5f; });
  ArrayPlacement place;
  place.threshold = 0.5;
  Check(a, place, 0);
}

TEST_F(ArrayStreamTest, RefusesWhatAnArrayCannotBe) {
  const TestArray a = MakeArray<float>("float32", {4, 4, 4}, false, [](auto...) { return 1.0f; });
  ArrayPlacement place;
  IngestOptions o;
  o.input = "a.npy";
  o.output = dir_.File("s");
  o.isovalue = 0.0;
  EXPECT_NE(IngestArray(a.view, place, o).status().message().find("--isovalue"), std::string::npos);
  o.isovalue.reset();
  o.color_grid = "Cd";
  EXPECT_NE(IngestArray(a.view, place, o).status().message().find("--color"), std::string::npos);
  o.color_grid.clear();
  std::filesystem::create_directory(o.output);
  EXPECT_NE(IngestArray(a.view, place, o).status().message().find("already exists"),
            std::string::npos);
  ArrayView bad = a.view;
  bad.dtype = "complex64";
  o.force = true;
  EXPECT_NE(IngestArray(bad, place, o).status().message().find("complex64"), std::string::npos);
}

}  // namespace
}  // namespace vox

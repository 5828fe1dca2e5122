// The main of every vox_test program (cmake/VoxHelpers.cmake): GoogleTest's
// own, except that a run where no test failed and at least one was skipped
// (GTEST_SKIP) exits 77, which vox_test gives ctest as SKIP_RETURN_CODE. So
// a program whose tests skipped (no memory cgroup, no read accounting)
// shows in ctest as "Skipped", not "Passed", and .ci/run can refuse it;
// a failure still shows as a failure.
#include <gtest/gtest.h>

#include <cstdio>

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  const int failed = RUN_ALL_TESTS();
  if (failed != 0) return failed;
  const int skipped = ::testing::UnitTest::GetInstance()->skipped_test_count();
  if (skipped == 0) return 0;
  std::printf("vox: %d test%s skipped: reported to ctest as skipped (exit 77)\n", skipped,
              skipped == 1 ? "" : "s");
  return 77;
}

// A test suite's own temporary directory holding the tools tests' store
// (WriteSphereShellStore, as "store"), made once for the suite and removed
// after it. Derive a fixture from it and use Path() and Write().
#ifndef VOX_TESTS_RENDER_STORE_SUITE_H_
#define VOX_TESTS_RENDER_STORE_SUITE_H_

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/render/store_util.h"

namespace vox::testing {

class SphereShellStoreSuite : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string suite = ::testing::UnitTest::GetInstance()->current_test_suite()->name();
    dir_ = new std::filesystem::path(std::filesystem::temp_directory_path() /
                                     ("vox_" + suite + "_" + std::to_string(getpid())));
    std::filesystem::create_directories(*dir_);
    Status s = WriteSphereShellStore(Path("store"));
    ASSERT_TRUE(s.ok()) << s.ToString();
  }
  static void TearDownTestSuite() {
    std::filesystem::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(Path(name)) << text;
    return Path(name);
  }

  static inline std::filesystem::path* dir_ = nullptr;
};

}  // namespace vox::testing

#endif  // VOX_TESTS_RENDER_STORE_SUITE_H_

// Regression for an input the exr fuzz target found: EXR headers whose
// attribute sizes claim more bytes than the file holds are refused, naming
// the file, before OpenEXR allocates what they claim; a real part still reads.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "render/exr.h"
#include "render/merge.h"

namespace vox {
namespace {

std::string Header(uint32_t size) {
  std::string h("\x76\x2f\x31\x01\x02\x02\x00\x00", 8);
  h += std::string("comments\0string\0", 16);
  for (int i = 0; i < 4; ++i) h.push_back(char((size >> (8 * i)) & 0xff));
  h += "abc";
  return h;
}

TEST(ExrHeader, AttributeLargerThanTheFileIsRefused) {
  const std::string path = "/tmp/vox-exr-header-" + std::to_string(getpid()) + ".exr";
  std::ofstream(path, std::ios::binary) << Header(1870004224u);
  auto info = ReadExrInfo(path);
  ASSERT_FALSE(info.ok());
  EXPECT_NE(info.status().message().find(path), std::string::npos) << info.status().ToString();
  EXPECT_NE(info.status().message().find("comments claims 1870004224 bytes"), std::string::npos)
      << info.status().ToString();
  EXPECT_FALSE(ReadExr(path).ok());
  EXPECT_FALSE(MergeParts({path}, path + ".out.exr").ok());
  // The same header with an honest size reaches OpenEXR, which reports the
  // missing attributes itself.
  std::ofstream(path, std::ios::binary) << Header(3);
  auto honest = ReadExrInfo(path);
  ASSERT_FALSE(honest.ok());
  EXPECT_EQ(honest.status().message().find("claims"), std::string::npos);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace vox

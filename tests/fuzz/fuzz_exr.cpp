// Fuzz target: vox-merge's input. The input holds two EXR parts (a 4-byte
// little-endian length, the first part, the second part), written to
// temporary files and merged. Any input must give a Status, never a crash
// (OpenEXR's own reader included: a crash there is a finding to report).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "render/merge.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 4) return 0;
  uint32_t len = uint32_t(data[0]) | uint32_t(data[1]) << 8 | uint32_t(data[2]) << 16 |
                 uint32_t(data[3]) << 24;
  if (len > size - 4) len = uint32_t(size - 4);
  static const std::string base = [] {
    const char* t = std::getenv("TMPDIR");
    return std::string(t && *t ? t : "/tmp") + "/vox-fuzz-exr-" + std::to_string(getpid());
  }();
  const std::string p1 = base + "-1.exr", p2 = base + "-2.exr", out = base + "-out.exr";
  std::ofstream(p1, std::ios::binary).write(reinterpret_cast<const char*>(data + 4), len);
  std::ofstream(p2, std::ios::binary)
      .write(reinterpret_cast<const char*>(data + 4 + len), std::streamsize(size - 4 - len));
  (void)vox::MergeParts({p1, p2}, out);
  std::remove(p1.c_str());
  std::remove(p2.c_str());
  std::remove(out.c_str());
  return 0;
}

// CheckFrameOutputs judges two output patterns, or a pattern and an input,
// from their shapes; here against the truth of expanding every frame of the
// range and comparing the names, over many pattern pairs and ranges, and at
// the largest sequence, where it must not go frame by frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "render/frame_sequence.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

bool Has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

class FrameOutputsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("vox_frame_outputs_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string P(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// Whether some frames n, m of `range` give a(n) == b(m), frame by frame.
bool Collide(const std::string& a, const std::string& b, FrameRange range) {
  std::set<std::string> names;
  for (int n = range.first; n <= range.last; ++n) names.insert(ExpandFramePattern(a, n));
  for (int m = range.first; m <= range.last; ++m)
    if (names.count(ExpandFramePattern(b, m))) return true;
  return false;
}

TEST_F(FrameOutputsTest, PatternPairsAgreeWithExpandingEveryFrame) {
  const std::vector<std::string> names = {"p.%d.exr", "p.%02d.exr", "p.%3d.exr", "p.1%d.exr",
                                          "p.%d0.exr", "p.%d.exr.json", "p.10.exr", "p.%04d.exr",
                                          "p.0%d.exr", "q%d.exr", "p.%d%%.exr", "p.7.exr"};
  const std::vector<FrameRange> ranges = {{1, 9}, {1, 12}, {10, 12}, {5, 120}, {100, 130}, {1, 1}};
  int collisions = 0;
  for (const FrameRange& r : ranges)
    for (size_t i = 0; i < names.size(); ++i)
      for (size_t j = i + 1; j < names.size(); ++j) {
        const std::string a = P(names[i]), b = P(names[j]);
        const bool truth = Collide(a, b, r);
        collisions += truth;
        Status s = CheckFrameOutputs({}, {{"-o", a}, {"--stats", b}}, r);
        EXPECT_EQ(!s.ok(), truth) << a << " " << b << " " << r.first << "-" << r.last << ": "
                                  << s.ToString();
        if (!s.ok()) EXPECT_TRUE(Has(s.message(), "are the same file")) << s.ToString();
      }
  EXPECT_GT(collisions, 10);  // the table has both kinds
}

TEST_F(FrameOutputsTest, AnInputAmongTheFramesIsFoundAndNamed) {
  std::ofstream(P("c7.json")) << "{}";
  fs::create_symlink(P("c7.json"), P("link.json"));
  Status s = CheckFrameOutputs({{"camera", P("link.json")}}, {{"--stats", P("c%d.json")}}, {1, 9});
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(Has(s.message(), "frame 7's --stats") && Has(s.message(), "destroy that input"))
      << s.ToString();
  EXPECT_TRUE(CheckFrameOutputs({{"camera", P("c7.json")}}, {{"--stats", P("c%d.json")}}, {8, 9})
                  .ok());
  // Spelled another way: the same directory.
  s = CheckFrameOutputs({{"camera", P("c7.json")}},
                        {{"--stats", (dir_ / "." / "c%d.json").string()}}, {1, 9});
  EXPECT_FALSE(s.ok()) << "./ spelling";
}

TEST_F(FrameOutputsTest, AMillionFramesAreCheckedAtOnce) {
  const auto t0 = std::chrono::steady_clock::now();
  Status s = CheckFrameOutputs({}, {{"-o", P("a.%07d.exr")}, {"--preview", P("a.%07d.png")},
                                    {"--stats", P("a.%07d.json")}, {"--save-cam", P("cams.json")}},
                               {1, kMaxFrames});
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(s.ok()) << s.ToString();
  EXPECT_LT(seconds, 0.1);
  s = CheckFrameOutputs({}, {{"-o", P("a.%07d.exr")}, {"--stats", P("a.%d.exr")}},
                        {1, kMaxFrames});
  EXPECT_TRUE(Has(s.message(), "frame 1000000's -o") && Has(s.message(), "same file"))
      << s.ToString();
}

TEST(MatchFramePatternTest, GivesTheFrameBack) {
  EXPECT_EQ(MatchFramePattern("a.%04d.exr", "a.0012.exr"), 12);
  EXPECT_EQ(MatchFramePattern("a.%04d.exr", "a.012.exr"), 0);
  EXPECT_EQ(MatchFramePattern("a.%d.exr", "a.012.exr"), 0);
  EXPECT_EQ(MatchFramePattern("a.%3d.exr", "a.  5.exr"), 5);
  EXPECT_EQ(MatchFramePattern("a%%.%d", "a%.3"), 3);
  EXPECT_EQ(MatchFramePattern("plain.exr", "plain.exr"), -1);
  EXPECT_EQ(MatchFramePattern("a.%d.exr", "a.0.exr"), 0);
}

}  // namespace
}  // namespace vox

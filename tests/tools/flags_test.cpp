// Tests of the tools' shared flag reading and number parsing
// (tools/common/flags.h).
#include "tools/common/flags.h"

#include <gtest/gtest.h>

#include <climits>
#include <cstdint>
#include <string>
#include <vector>

namespace vox {
namespace {

FlagReader Reader(const std::vector<const char*>& args) {
  std::vector<const char*> argv = {"prog"};
  argv.insert(argv.end(), args.begin(), args.end());
  return FlagReader(int(argv.size()), argv.data());
}

TEST(FlagReaderTest, WalksFlagsValuesAndPositionals) {
  FlagReader r = Reader({"in.vdb", "--grid", "density", "-", "--quiet", "-o", "out"});
  std::vector<std::string> seen;
  while (r.Next()) {
    if (r.IsFlag() && r.arg() != "--quiet") {
      const std::string flag = r.arg();
      auto v = r.Value();
      ASSERT_TRUE(v.has_value()) << flag;
      seen.push_back(flag + "=" + *v);
    } else {
      seen.push_back(std::string(r.IsFlag() ? "flag:" : "arg:") + r.arg());
    }
  }
  EXPECT_EQ(seen, (std::vector<std::string>{"arg:in.vdb", "--grid=density", "arg:-",
                                            "flag:--quiet", "-o=out"}));
  EXPECT_FALSE(r.Next());  // stays at the end
}

TEST(FlagReaderTest, MissingValueAtTheEnd) {
  FlagReader r = Reader({"--threads"});
  ASSERT_TRUE(r.Next());
  EXPECT_FALSE(r.Value().has_value());
  EXPECT_EQ(r.arg(), "--threads");
  EXPECT_FALSE(r.Next());
}

TEST(FlagReaderTest, HelpAndCommandLine) {
  FlagReader none = Reader({});
  EXPECT_FALSE(none.Next());
  EXPECT_EQ(none.CommandLine("vox-x"), "vox-x");
  FlagReader r = Reader({"-h", "--help", "--helpful", "a b"});
  std::vector<bool> help;
  while (r.Next()) help.push_back(r.IsHelp());
  EXPECT_EQ(help, (std::vector<bool>{true, true, false, false}));
  EXPECT_EQ(r.CommandLine("vox-x"), "vox-x -h --help --helpful a b");
}

TEST(ParseIntTest, AcceptsWholeNumbersInRange) {
  int v = 7;
  EXPECT_TRUE(ParseInt("12", 8, 16, &v));
  EXPECT_EQ(v, 12);
  EXPECT_TRUE(ParseInt("-3", -5, 5, &v));
  EXPECT_EQ(v, -3);
  EXPECT_TRUE(ParseInt("+8", 8, 16, &v));
  EXPECT_EQ(v, 8);
  EXPECT_TRUE(ParseInt("16", 8, 16, &v));  // both ends included
  EXPECT_EQ(v, 16);
  int64_t big = 0;
  EXPECT_TRUE(ParseInt("9007199254740993", 0, INT64_MAX, &big));
  EXPECT_EQ(big, int64_t(9007199254740993));
}

TEST(ParseIntTest, RefusesAndLeavesTheOutputAlone) {
  for (const char* bad : {"", "abc", "12.5", "12x", "7", "17", "1e3", "0x10", "99999999999999999999"}) {
    int v = 42;
    EXPECT_FALSE(ParseInt(bad, 8, 16, &v)) << bad;
    EXPECT_EQ(v, 42) << bad;
  }
  int64_t v = 5;
  EXPECT_FALSE(ParseInt("-1", 0, INT64_MAX, &v));
  EXPECT_FALSE(ParseInt("9223372036854775808", INT64_MIN, INT64_MAX, &v));  // overflows
  EXPECT_EQ(v, 5);
  int i = 0;
  EXPECT_FALSE(ParseInt("2147483648", INT_MIN, INT_MAX, &i));  // beyond int
}

TEST(ParseDoubleTest, FiniteNumbersOnly) {
  double d = 0;
  EXPECT_TRUE(ParseDouble("-0.25", &d));
  EXPECT_EQ(d, -0.25);
  EXPECT_TRUE(ParseDouble("0x1.8p1", &d));
  EXPECT_EQ(d, 3.0);
  EXPECT_TRUE(ParseDouble("1e3", &d));
  EXPECT_EQ(d, 1000.0);
  for (const char* bad : {"", "nan", "inf", "-inf", "1e999", "1.5f", "one"}) {
    d = 9;
    EXPECT_FALSE(ParseDouble(bad, &d)) << bad;
    EXPECT_EQ(d, 9) << bad;
  }
}

TEST(SplitListTest, KeepsEmptyItems) {
  EXPECT_EQ(SplitList("normal,voxel"), (std::vector<std::string>{"normal", "voxel"}));
  EXPECT_EQ(SplitList("a,,b,"), (std::vector<std::string>{"a", "", "b", ""}));
  EXPECT_EQ(SplitList(""), (std::vector<std::string>{""}));
  EXPECT_EQ(SplitList("x:y", ':'), (std::vector<std::string>{"x", "y"}));
}

}  // namespace
}  // namespace vox

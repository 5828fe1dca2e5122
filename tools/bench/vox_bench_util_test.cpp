// Tests of vox-bench's helpers: medians, tables, the SVG plot, masks and
// their comparisons, PPM reading (and its errors), shelling out.
#include "tools/bench/vox_bench_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <string>

namespace vox::bench {
namespace {

int Count(const std::string& s, const std::string& what) {
  int n = 0;
  for (size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/vox_bench_util_test_" + std::to_string(getpid()) + "_" + name;
}

TEST(VoxBenchUtil, Median) {
  EXPECT_EQ(Median({3, 1, 2}), 2);
  EXPECT_EQ(Median({4, 1, 3, 2}), 2.5);
  EXPECT_TRUE(std::isnan(Median({})));
}

TEST(VoxBenchUtil, TableMarkdownAndCsv) {
  Table t({"name", "value"});
  t.Add({"**bold**", "1,5"});
  t.Add({"say \"hi\"", "`x`"});
  EXPECT_EQ(t.Markdown(), "| name | value |\n| --- | --- |\n| **bold** | 1,5 |\n| say \"hi\" | `x` |\n");
  // Emphasis is not data; commas and quotes are quoted.
  EXPECT_EQ(t.Csv(), "name,value\nbold,\"1,5\"\n\"say \"\"hi\"\"\",x\n");
}

TEST(VoxBenchUtil, SvgPlotHasAxesLegendAndEveryPoint) {
  PlotSpec spec;
  spec.title = "T <1>";
  spec.x_label = "ns per ray";
  spec.y_label = "error rate";
  spec.log_x = spec.log_y = true;
  Series a{"fixed", {{100, 1e-3}, {2000, 0.5}}, {"p", "q"}, false};
  Series b{"float", {{300, 1e-3}, {300, 1e-3}, {-1, 0.1}}, {"same1", "same2", "bad"}, true};
  std::string svg = SvgPlot(spec, {a, b});
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  EXPECT_NE(svg.find("T &lt;1&gt;"), std::string::npos);  // escaped title
  EXPECT_NE(svg.find("ns per ray (log scale)"), std::string::npos);
  EXPECT_NE(svg.find("error rate (log scale)"), std::string::npos);
  // 4 drawable points + 2 legend markers; the x <= 0 point is left out on a log axis.
  EXPECT_EQ(Count(svg, "<circle"), 6);
  EXPECT_EQ(Count(svg, ">bad</text>"), 0);
  // Decade ticks cover the data: 100 .. 10000 and 1e-3 .. 1.
  EXPECT_NE(svg.find(">100</text>"), std::string::npos);
  EXPECT_NE(svg.find(">10000</text>"), std::string::npos);
  EXPECT_NE(svg.find(">0.001</text>"), std::string::npos);
  // Two labels at the same point are drawn at different heights.
  size_t p1 = svg.find(">same1</text>"), p2 = svg.find(">same2</text>");
  ASSERT_NE(p1, std::string::npos);
  ASSERT_NE(p2, std::string::npos);
  auto y_of = [&](size_t p) {
    size_t t = svg.rfind("<text", p);
    size_t y = svg.find(" y=\"", t);
    return std::stod(svg.substr(y + 4));
  };
  EXPECT_GT(std::fabs(y_of(p1) - y_of(p2)), 8.0);
}

TEST(VoxBenchUtil, SvgPlotLinearAxisWithoutData) {
  PlotSpec spec;
  std::string svg = SvgPlot(spec, {});
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
}

Image MakeMask(int w, int h, std::vector<uint8_t> m, float lum) {
  Image im;
  im.width = w;
  im.height = h;
  im.mask = std::move(m);
  im.rgb.assign(im.mask.size() * 3, lum);
  return im;
}

TEST(VoxBenchUtil, MaskComparisons) {
  Image a = MakeMask(2, 2, {1, 1, 0, 0}, 0.5f);
  Image b = MakeMask(2, 2, {1, 0, 1, 0}, 0.75f);
  EXPECT_DOUBLE_EQ(MaskIoU(a, b), 1.0 / 3.0);
  EXPECT_EQ(MaskDifferences(a, b), 2u);
  EXPECT_DOUBLE_EQ(MeanAbsShadingDiff(a, b), 0.25);  // over the one pixel both cover
  Image empty = MakeMask(2, 2, {0, 0, 0, 0}, 0.0f);
  EXPECT_EQ(MaskIoU(empty, empty), 1.0);
  EXPECT_EQ(MeanAbsShadingDiff(empty, a), 0.0);
}

TEST(VoxBenchUtil, ReadPpmAndMaskByLuminance) {
  std::string path = TempPath("a.ppm");
  std::string data = "P6\n2 1\n255\n";
  data += std::string("\xff\xff\xff", 3);  // white: hit
  data += std::string("\x10\x00\x00", 3);  // dark: background
  ASSERT_TRUE(WriteFile(path, data).ok());
  auto im = ReadPpm(path);
  ASSERT_TRUE(im.ok()) << im.status().ToString();
  EXPECT_EQ(im->width, 2);
  EXPECT_EQ(im->height, 1);
  EXPECT_EQ(im->mask, (std::vector<uint8_t>{1, 0}));
  EXPECT_FLOAT_EQ(im->rgb[0], 1.0f);

  ASSERT_TRUE(WriteFile(path, "P6\n2 2\n255\nabc").ok());  // truncated
  auto bad = ReadPpm(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find(path), std::string::npos);
  EXPECT_NE(bad.status().ToString().find("truncated"), std::string::npos);

  ASSERT_TRUE(WriteFile(path, "P3\n1 1\n255\n0 0 0\n").ok());  // ASCII PPM
  bad = ReadPpm(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find("binary PPM"), std::string::npos);

  bad = ReadPpm(TempPath("missing.ppm"));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find("missing.ppm"), std::string::npos);
  unlink(path.c_str());
}

TEST(VoxBenchUtil, RunCommand) {
  auto ok = RunCommand("echo hi; echo err 1>&2");
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(*ok, "hi\nerr\n");
  auto bad = RunCommand("echo boom; exit 3");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find("boom"), std::string::npos);
  EXPECT_EQ(Quote("a'b"), "'a'\\''b'");
  auto quoted = RunCommand("printf %s " + Quote("it's $HOME"));
  ASSERT_TRUE(quoted.ok());
  EXPECT_EQ(*quoted, "it's $HOME");
}

TEST(VoxBenchUtil, WriteFileReportsThePath) {
  Status s = WriteFile("/nonexistent-dir-vox/x.md", "x");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.ToString().find("/nonexistent-dir-vox/x.md"), std::string::npos);
}

}  // namespace
}  // namespace vox::bench

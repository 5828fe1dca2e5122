// Tests of the shared progress display (core/util/progress.h) in the modes a test
// can capture: plain lines at each 10% step, the bar's drawing, quiet.
#include "core/util/progress.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

namespace vox {
namespace {

// Everything written to a temporary FILE*.
class Capture {
 public:
  Capture() : f_(std::tmpfile()) {}
  ~Capture() { std::fclose(f_); }
  FILE* file() { return f_; }
  std::string Text() {
    std::fflush(f_);
    std::string s;
    std::rewind(f_);
    for (int c; (c = std::fgetc(f_)) != EOF;) s.push_back(char(c));
    return s;
  }

 private:
  FILE* f_;
};

Progress::Text Count(uint64_t done, uint64_t total) {
  return [=](double) { return std::to_string(done) + "/" + std::to_string(total); };
}

TEST(ProgressDisplayTest, PlainPrintsEachTenPercentStepOnce) {
  Capture out;
  Progress p(ProgressMode::kPlain, out.file());
  for (uint64_t d = 1; d <= 40; ++d) p.Update(d, 40, Count(d, 40));
  p.Finish(40, 40, Count(40, 40));
  // Steps 0..10 of 40 units: the first unit (step 0), then 4, 8, ..., 40.
  EXPECT_EQ(out.Text(), "1/40\n4/40\n8/40\n12/40\n16/40\n20/40\n24/40\n28/40\n32/40\n36/40\n40/40\n");
}

TEST(ProgressDisplayTest, PlainWithoutFirstStepAndJumps) {
  Capture out;
  ProgressStyle style;
  style.plain_first_step = false;
  Progress p(ProgressMode::kPlain, out.file(), style);
  p.Update(1, 100, Count(1, 100));    // step 0: not shown
  p.Update(35, 100, Count(35, 100));  // jumps to step 3
  p.Update(39, 100, Count(39, 100));  // still step 3
  p.Update(40, 100, Count(40, 100), /*force=*/true);
  p.Message("phase two");
  p.Finish(90, 100, Count(90, 100));  // the final report was not out yet
  EXPECT_EQ(out.Text(), "35/100\n40/100\nphase two\n90/100\n");
}

TEST(ProgressDisplayTest, BarRedrawsInPlaceAndEndsItsLine) {
  Capture out;
  ProgressStyle style;
  style.bar_width = 4;
  style.clear_to_line_end = false;
  Progress p(ProgressMode::kBar, out.file(), style);
  p.Update(1, 4, Count(1, 4));  // the first report is drawn at once
  p.Update(4, 4, Count(4, 4));  // the end is always drawn
  p.Message("done");
  p.Finish(4, 4, Count(4, 4));  // already shown, no bar on screen: nothing
  EXPECT_EQ(out.Text(), "\r[#---] 1/4\r[####] 4/4\ndone\n");
}

TEST(ProgressDisplayTest, FinishDrawsTheEndOnceAndQuietWritesNothing) {
  Capture out;
  Progress p(ProgressMode::kBar, out.file());
  p.Finish(0, 0, [](double) { return std::string("empty"); });
  EXPECT_EQ(out.Text(), "\r[########################] empty\033[K\n");
  Capture none;
  Progress q(ProgressMode::kQuiet, none.file());
  q.Update(1, 1, Count(1, 1), true);
  q.Message("x");
  q.Finish(1, 1, Count(1, 1));
  EXPECT_EQ(none.Text(), "");
}

TEST(ProgressDisplayTest, CountAndDurationTexts) {
  EXPECT_EQ(Progress::Count(950), "950");
  EXPECT_EQ(Progress::Count(12345), "12.3k");
  EXPECT_EQ(Progress::Count(4.56e6), "4.56M");
  EXPECT_EQ(Progress::Count(7.891e9), "7.89G");
  EXPECT_EQ(Progress::Duration(4.24), "4.2s");
  EXPECT_EQ(Progress::Duration(185), "3m05s");
  EXPECT_EQ(Progress::Duration(3720), "1h02m");
  EXPECT_EQ(Progress::Duration(INFINITY), "?");
}

}  // namespace
}  // namespace vox

// vox::Progress: the one progress display of vox's long-running work
// (vox-ingest's bricks, vox-render's tiles). On a terminal, a bar redrawn in
// place at most every 100 ms; otherwise (logs, Slurm) a plain line each time
// the work enters another 10% step; nothing when quiet. The caller supplies
// the text of a report (what was done, rates); the display decides when and
// how to draw it. ProgressStyle keeps each program's look.
//
// Thread safety: Update may be called from any thread and never blocks the
// caller (a report that finds another being drawn is dropped); Message and
// Finish wait for the display.
#ifndef VOX_CORE_UTIL_PROGRESS_H_
#define VOX_CORE_UTIL_PROGRESS_H_

#include <cstdint>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>

#include "core/util/stopwatch.h"

namespace vox {

enum class ProgressMode { kQuiet, kPlain, kBar };

// kBar when `stream` is a terminal, else kPlain; kQuiet when quiet.
ProgressMode ChooseProgressMode(FILE* stream, bool quiet);

struct ProgressStyle {
  int bar_width = 24;            // characters between the brackets
  char bar_empty = '-';          // the bar's unfilled part
  bool clear_to_line_end = true;  // erase what a longer earlier text left behind
  // Plain mode: also print the first report when it is below 10%.
  bool plain_first_step = true;
};

class Progress {
 public:
  // The text of one report, given the seconds since the display started.
  // Called only when the report is drawn.
  using Text = std::function<std::string(double elapsed_seconds)>;

  Progress(ProgressMode mode, FILE* out, ProgressStyle style = {});

  // `done` of `total` units finished. Drawn in bar mode when 100 ms have
  // passed since the last drawing, when done == total or when forced; in
  // plain mode when done enters another 10% step or when forced.
  void Update(uint64_t done, uint64_t total, const Text& text, bool force = false);

  // A line of its own (ends the bar's line first). Not shown when quiet.
  void Message(std::string_view line);

  // The end: draws the final report unless it is already shown, and ends the
  // bar's line.
  void Finish(uint64_t done, uint64_t total, const Text& text);

  // Pieces for report texts: 950, 12.3k, 4.56M, 7.89G; 4.2s, 3m05s, 1h02m
  // ("?" when not finite).
  static std::string Count(double v);
  static std::string Duration(double seconds);

 private:
  void Draw(uint64_t done, uint64_t total, const Text& text);  // mu_ held
  void EndBarLine();                                            // mu_ held

  const ProgressMode mode_;
  FILE* const out_;
  const ProgressStyle style_;
  std::mutex mu_;
  Stopwatch clock_;
  double last_draw_ = -1;  // clock_ seconds of the last drawing; < 0: none yet
  int last_step_;          // plain mode: the 10% step of the last line
  bool bar_on_screen_ = false;
  bool final_shown_ = false;
};

}  // namespace vox

#endif  // VOX_CORE_UTIL_PROGRESS_H_

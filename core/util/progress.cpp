#include "core/util/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace vox {

ProgressMode ChooseProgressMode(FILE* stream, bool quiet) {
  if (quiet) return ProgressMode::kQuiet;
  return isatty(fileno(stream)) ? ProgressMode::kBar : ProgressMode::kPlain;
}

Progress::Progress(ProgressMode mode, FILE* out, ProgressStyle style)
    : mode_(mode), out_(out), style_(style), last_step_(style.plain_first_step ? -1 : 0) {}

std::string Progress::Count(double v) {
  char buf[32];
  if (v >= 1e9)
    std::snprintf(buf, sizeof buf, "%.2fG", v / 1e9);
  else if (v >= 1e6)
    std::snprintf(buf, sizeof buf, "%.2fM", v / 1e6);
  else if (v >= 1e3)
    std::snprintf(buf, sizeof buf, "%.1fk", v / 1e3);
  else
    std::snprintf(buf, sizeof buf, "%.0f", v);
  return buf;
}

std::string Progress::Duration(double s) {
  char buf[32];
  if (!std::isfinite(s)) return "?";
  if (s >= 3600)
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s / 3600), int(std::fmod(s, 3600) / 60));
  else if (s >= 60)
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s / 60), int(std::fmod(s, 60)));
  else
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  return buf;
}

void Progress::Draw(uint64_t done, uint64_t total, const Text& text) {
  const double now = clock_.Seconds();
  last_draw_ = now;
  final_shown_ = done == total;
  const std::string line = text(now);
  if (mode_ == ProgressMode::kBar) {
    const uint64_t width = uint64_t(style_.bar_width);
    const uint64_t filled = total > 0 ? std::min(done, total) * width / total : width;
    const std::string bar = "[" + std::string(size_t(filled), '#') +
                            std::string(size_t(width - filled), style_.bar_empty) + "] ";
    std::fprintf(out_, "\r%s%s%s", bar.c_str(), line.c_str(),
                 style_.clear_to_line_end ? "\033[K" : "");
    bar_on_screen_ = true;
  } else {
    std::fprintf(out_, "%s\n", line.c_str());
  }
  std::fflush(out_);
}

void Progress::EndBarLine() {
  if (!bar_on_screen_) return;
  std::fprintf(out_, "\n");
  std::fflush(out_);
  bar_on_screen_ = false;
}

void Progress::Update(uint64_t done, uint64_t total, const Text& text, bool force) {
  if (mode_ == ProgressMode::kQuiet) return;
  std::unique_lock<std::mutex> lock(mu_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  if (mode_ == ProgressMode::kBar) {
    const bool due = last_draw_ < 0 || clock_.Seconds() - last_draw_ >= 0.1;
    if (!force && !due && done != total) return;
  } else {
    const int step = total > 0 ? int(10 * done / total) : 10;
    if (!force && step == last_step_) return;
    last_step_ = step;
  }
  Draw(done, total, text);
}

void Progress::Message(std::string_view line) {
  if (mode_ == ProgressMode::kQuiet) return;
  std::lock_guard<std::mutex> lock(mu_);
  EndBarLine();
  std::fprintf(out_, "%.*s\n", int(line.size()), line.data());
  std::fflush(out_);
}

void Progress::Finish(uint64_t done, uint64_t total, const Text& text) {
  if (mode_ == ProgressMode::kQuiet) return;
  std::lock_guard<std::mutex> lock(mu_);
  if (!final_shown_) Draw(done, total, text);
  EndBarLine();
}

}  // namespace vox

#include "render/progress.h"

#include <unistd.h>

#include <cmath>

namespace vox {

ProgressMode ChooseProgressMode(FILE* stream, bool quiet) {
  if (quiet) return ProgressMode::kQuiet;
  return isatty(fileno(stream)) ? ProgressMode::kBar : ProgressMode::kPlain;
}

Progress::Progress(ProgressMode mode, FILE* out) : mode_(mode), out_(out) {
  start_ = last_ = std::chrono::steady_clock::now();
}

namespace {

std::string Human(double v) {
  char buf[32];
  if (v >= 1e9)
    snprintf(buf, sizeof buf, "%.2fG", v / 1e9);
  else if (v >= 1e6)
    snprintf(buf, sizeof buf, "%.2fM", v / 1e6);
  else if (v >= 1e3)
    snprintf(buf, sizeof buf, "%.1fk", v / 1e3);
  else
    snprintf(buf, sizeof buf, "%.0f", v);
  return buf;
}

std::string Duration(double s) {
  char buf[32];
  if (!std::isfinite(s)) return "?";
  if (s >= 3600)
    snprintf(buf, sizeof buf, "%dh%02dm", int(s / 3600), int(std::fmod(s, 3600) / 60));
  else if (s >= 60)
    snprintf(buf, sizeof buf, "%dm%02ds", int(s / 60), int(std::fmod(s, 60)));
  else
    snprintf(buf, sizeof buf, "%.1fs", s);
  return buf;
}

}  // namespace

std::string Progress::Line(const ProgressSnapshot& s, double elapsed) {
  double frac = s.tiles_total > 0 ? double(s.tiles_done) / double(s.tiles_total) : 1.0;
  double rate = elapsed > 0 ? double(s.rays) / elapsed : 0.0;
  uint64_t lookups = s.cache_hits + s.cache_misses;
  std::string cache =
      lookups > 0
          ? std::to_string(int(std::lround(100.0 * double(s.cache_hits) / double(lookups)))) + "%"
          : "-";
  double left = frac > 0 ? elapsed * (1.0 - frac) / frac : INFINITY;
  char buf[256];
  snprintf(buf, sizeof buf,
           "tiles %lld/%lld (%3.0f%%)  %s rays/s  cache hits %s  elapsed %s  left %s",
           (long long)s.tiles_done, (long long)s.tiles_total, 100.0 * frac, Human(rate).c_str(),
           cache.c_str(), Duration(elapsed).c_str(), Duration(left).c_str());
  return buf;
}

void Progress::Draw(const ProgressSnapshot& s, double elapsed) {
  std::string line = Line(s, elapsed);
  if (mode_ == ProgressMode::kBar) {
    const int width = 24;
    double frac = s.tiles_total > 0 ? double(s.tiles_done) / double(s.tiles_total) : 1.0;
    int filled = int(frac * width);
    std::string bar =
        "[" + std::string(size_t(filled), '#') + std::string(size_t(width - filled), '-') + "] ";
    fprintf(out_, "\r%s%s\033[K", bar.c_str(), line.c_str());
  } else {
    fprintf(out_, "%s\n", line.c_str());
  }
  fflush(out_);
}

void Progress::Update(const ProgressSnapshot& s, bool force) {
  if (mode_ == ProgressMode::kQuiet) return;
  std::unique_lock<std::mutex> lock(mu_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  auto now = std::chrono::steady_clock::now();
  double elapsed = std::chrono::duration<double>(now - start_).count();
  if (mode_ == ProgressMode::kBar) {
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
  } else {
    int decile = s.tiles_total > 0 ? int(10 * s.tiles_done / s.tiles_total) : 10;
    if (!force && decile == last_decile_) return;
    last_decile_ = decile;
  }
  last_ = now;
  Draw(s, elapsed);
}

void Progress::Finish(const ProgressSnapshot& s) {
  if (mode_ == ProgressMode::kQuiet) return;
  std::lock_guard<std::mutex> lock(mu_);
  double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (mode_ == ProgressMode::kPlain && last_decile_ == 10) return;  // the 100% line is out
  Draw(s, elapsed);
  if (mode_ == ProgressMode::kBar) fprintf(out_, "\n");
  fflush(out_);
}

}  // namespace vox

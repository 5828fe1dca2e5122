// vox::MakeStderrProgress: the progress display of vox-ingest.
#include <chrono>
#include <cstdio>
#include <string>

#include "ingest/ingest.h"

namespace vox {
namespace {

class StderrProgress : public ProgressSink {
 public:
  explicit StderrProgress(bool terminal) : terminal_(terminal) {}

  void Message(std::string_view line) override {
    ClearBar();
    std::fprintf(stderr, "%.*s\n", int(line.size()), line.data());
  }

  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (total == 0) return;
    const int percent = int(done * 100 / total);
    if (terminal_) {
      auto now = std::chrono::steady_clock::now();
      if (done != total && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      constexpr int kWidth = 40;
      int fill = int(done * kWidth / total);
      std::string bar(size_t(fill), '#');
      bar.append(size_t(kWidth - fill), ' ');
      std::fprintf(stderr, "\r[%s] %3d%% %llu/%llu bricks, %llu voxels", bar.c_str(), percent,
                   (unsigned long long)done, (unsigned long long)total,
                   (unsigned long long)voxels);
      std::fflush(stderr);
      bar_shown_ = true;
    } else if (percent >= next_percent_ || done == total) {
      std::fprintf(stderr, "%3d%% %llu/%llu bricks, %llu voxels\n", percent,
                   (unsigned long long)done, (unsigned long long)total,
                   (unsigned long long)voxels);
      while (next_percent_ <= percent) next_percent_ += 10;
    }
  }

  void Done() override { ClearBar(); }

 private:
  void ClearBar() {
    if (bar_shown_) {
      std::fprintf(stderr, "\n");
      bar_shown_ = false;
    }
  }

  bool terminal_;
  bool bar_shown_ = false;
  int next_percent_ = 10;
  std::chrono::steady_clock::time_point last_draw_{};
};

}  // namespace

std::unique_ptr<ProgressSink> MakeStderrProgress(bool terminal) {
  return std::make_unique<StderrProgress>(terminal);
}

}  // namespace vox

// vox::Progress: what vox-render shows while it works. On a terminal, a bar
// redrawn in place (tiles done, rays per second, cache hit rate, time left);
// otherwise plain lines every 10% (logs, Slurm); nothing when quiet.
//
// Thread safety: Update may be called from any thread; it draws at most every
// 100 ms and never blocks the caller (try_lock).
#ifndef VOX_RENDER_PROGRESS_H_
#define VOX_RENDER_PROGRESS_H_

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>

namespace vox {

enum class ProgressMode { kQuiet, kPlain, kBar };

// kBar when `stream` is a terminal, else kPlain; kQuiet when quiet.
ProgressMode ChooseProgressMode(FILE* stream, bool quiet);

struct ProgressSnapshot {
  int64_t tiles_done = 0, tiles_total = 0;
  uint64_t rays = 0;
  uint64_t cache_hits = 0, cache_misses = 0;  // bricks entered without / with paging in
};

class Progress {
 public:
  Progress(ProgressMode mode, FILE* out);
  void Update(const ProgressSnapshot& s, bool force = false);
  void Finish(const ProgressSnapshot& s);
  // The text of one progress report (without the bar), for tests and logs.
  static std::string Line(const ProgressSnapshot& s, double elapsed_seconds);

 private:
  void Draw(const ProgressSnapshot& s, double elapsed);
  ProgressMode mode_;
  FILE* out_;
  std::mutex mu_;
  std::chrono::steady_clock::time_point start_, last_;
  int last_decile_ = -1;
};

}  // namespace vox

#endif  // VOX_RENDER_PROGRESS_H_

// vox::Stopwatch: wall-clock seconds (steady clock) for timings and progress.
// Starts when constructed; Restart() starts it again and Lap() reads and
// restarts in one step (consecutive phases of a job).
//
// Thread safety: reading (Seconds) is safe from any thread; Restart and Lap
// need external synchronisation.
#ifndef VOX_CORE_UTIL_STOPWATCH_H_
#define VOX_CORE_UTIL_STOPWATCH_H_

#include <chrono>

namespace vox {

class Stopwatch {
 public:
  using Clock = std::chrono::steady_clock;

  Stopwatch() : start_(Clock::now()) {}

  // Seconds since construction or the last Restart/Lap.
  double Seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

  void Restart() { start_ = Clock::now(); }

  // Seconds since construction or the last Restart/Lap, and restarts.
  double Lap() {
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - start_).count();
    start_ = now;
    return s;
  }

 private:
  Clock::time_point start_;
};

}  // namespace vox

#endif  // VOX_CORE_UTIL_STOPWATCH_H_

// The TSan gate's planted race (tests/core/CMakeLists.txt): tasks run by the
// executor of the tile workers (RunWorkers) or of the ingest's brick pipeline
// (RunPipeline, in its parallel stage) increment one global without a lock.
// ThreadSanitizer must report it: the tests tsan_planted_race_workers and
// tsan_planted_race_pipeline pass only if this program fails with a data race
// report naming PlantedRace. `control` does the same under a mutex and must
// pass without a report.
//   tsan_planted_race workers|pipeline|control
#include <chrono>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <thread>

#include "core/util/parallel.h"

namespace {

long g_counter = 0;  // the raced global
std::mutex g_mu;

// noinline: the report's stack names it.
__attribute__((noinline)) void PlantedRace() { g_counter = g_counter + 1; }

__attribute__((noinline)) void Guarded() {
  std::lock_guard<std::mutex> lock(g_mu);
  g_counter = g_counter + 1;
}

struct Item {
  int index = 0;
};

void Pipeline(void (*touch)()) {
  int next = 0;
  vox::RunPipeline<Item>(
      4, 8,
      [&](Item& it) {
        if (next == 200) return false;
        it.index = next++;
        return true;
      },
      [&](Item&) {
        // TSan orders what the executor's hand-overs order: a race shows when
        // two items' work overlaps in time, as real bricks' work does.
        touch();
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      },
      [&](Item&) {});
}

}  // namespace

int main(int argc, char** argv) {
  const char* mode = argc == 2 ? argv[1] : "";
  if (std::strcmp(mode, "workers") == 0) {
    vox::RunWorkers(4, [](int) {
      for (int i = 0; i < 1000; ++i) PlantedRace();
    });
  } else if (std::strcmp(mode, "pipeline") == 0) {
    Pipeline(PlantedRace);
  } else if (std::strcmp(mode, "control") == 0) {
    vox::RunWorkers(4, [](int) {
      for (int i = 0; i < 1000; ++i) Guarded();
    });
    Pipeline(Guarded);
    if (g_counter != 4200) {
      std::fprintf(stderr, "control: %ld increments, expected 4200\n", g_counter);
      return 1;
    }
  } else {
    std::fprintf(stderr, "usage: tsan_planted_race workers|pipeline|control\n");
    return 2;
  }
  std::printf("%s: %ld increments (%s threads)\n", mode, g_counter,
              vox::PlainThreads() ? "plain" : "TBB");
  return 0;
}

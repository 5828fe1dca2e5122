// The TSan stage's self-test: a data race in vox-compiled code run as the
// tile workers run (render/frame.cpp: a tbb::task_arena of `threads`, a
// tbb::parallel_for of one body per thread). ThreadSanitizer must report it
// with the project's suppressions in force (scripts/sanitizer/tsan.supp);
// the ctest around it (tests/render/CMakeLists.txt) fails when it does not.
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cstdio>

namespace {

long g_counter = 0;  // written by every worker, unguarded: the planted race

[[gnu::noinline]] void Work(int rounds) {
  for (int i = 0; i < rounds; ++i) g_counter = g_counter + 1;
}

}  // namespace

int main() {
  const int threads = 4;
  tbb::task_arena arena(threads);
  arena.execute([&] { tbb::parallel_for(0, threads, [&](int) { Work(100000); }); });
  std::printf("the planted race ran unreported (counter %ld)\n", g_counter);
  return 0;
}

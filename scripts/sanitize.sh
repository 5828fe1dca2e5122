#!/usr/bin/env bash
# Sanitizer builds and their tests (run by .ci/run after the normal suite).
#   scripts/sanitize.sh asan   ASan + UBSan build in build-asan/ (every finding fatal),
#                              then the default test suite (no "long" tests) in it.
#   scripts/sanitize.sh tsan   TSan build in build-tsan/ of the threaded tests only:
#                              the brick cache (many threads, tiny budget, injected load
#                              failures), prefetch, the store writer, tiled rendering
#                              and vox-render/vox-merge. tools_gen_test is left out: its
#                              brute-force checks are single-threaded and TSan slows
#                              them past the test's time limit (docs/robustness.md).
# The OpenVDB ingest tests are left out of TSan: OpenVDB and TBB are not built
# with TSan, so their internal synchronisation is invisible to it (false
# reports), and each OpenVDB test takes minutes to build instrumented. ASan
# covers them.
# Tests that measure memory (RSS, cgroups) or tight time limits check
# VOX_SANITIZED and skip those checks: shadow memory and quarantine change
# what they measure.
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-}"
jobs="${VOX_JOBS:-$(nproc)}"
gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)

case "$mode" in
  asan)
    dir=build-asan
    [ -f "$dir/CMakeCache.txt" ] && gen=()
    cmake -S . -B "$dir" "${gen[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release \
      -DVOX_SANITIZE=address,undefined -DVOX_BUILD_BENCH=OFF
    cmake --build "$dir" -j "$jobs"
    export ASAN_OPTIONS="detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=0:check_initialization_order=1:${ASAN_OPTIONS:-}"
    export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
    export LSAN_OPTIONS="suppressions=$PWD/scripts/sanitizer/lsan.supp:${LSAN_OPTIONS:-}"
    ctest --test-dir "$dir" --output-on-failure -LE long -j "$jobs" --timeout 1800
    ;;
  tsan)
    dir=build-tsan
    [ -f "$dir/CMakeCache.txt" ] && gen=()
    tests=(storage_cache_test storage_cache_stress_test storage_prefetch_test storage_writer_test
           render_frame_test render_cli_test render_memory_budget_test)
    cmake -S . -B "$dir" "${gen[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release \
      -DVOX_SANITIZE=thread -DVOX_BUILD_BENCH=OFF
    cmake --build "$dir" -j "$jobs" --target "${tests[@]}"
    export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/scripts/sanitizer/tsan.supp:${TSAN_OPTIONS:-}"
    regex="^($(IFS='|'; echo "${tests[*]}"))\$"
    ctest --test-dir "$dir" --output-on-failure -R "$regex" -j "$jobs" --timeout 1800
    ;;
  *)
    echo "usage: scripts/sanitize.sh asan|tsan" >&2
    exit 2
    ;;
esac

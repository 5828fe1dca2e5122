#!/usr/bin/env bash
# Sanitizer builds and their tests (run by .ci/run after the normal suite).
#   scripts/sanitize.sh asan   ASan + UBSan build with clang in build-asan/ (every finding
#                              fatal). It also carries libFuzzer's coverage instrumentation
#                              (fuzzer-no-link), so the fuzz targets come from the same
#                              build. Runs CI's set of tests (below; the tests that have run
#                              clean under this build), or with VOX_ASAN_SUITE=full the whole
#                              default suite (no "long" tests); then each libFuzzer target
#                              of VOX_FUZZ_TARGETS (default store,parse) for
#                              VOX_FUZZ_SECONDS (default 25; 0: none) through scripts/fuzz.sh.
#   scripts/sanitize.sh tsan   TSan build (gcc) in build-tsan/ of the threaded tests only:
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
# VOX_ASAN_DIR overrides the ASan build directory (also read by scripts/fuzz.sh).
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
    dir="${VOX_ASAN_DIR:-build-asan}"
    [ -f "$dir/CMakeCache.txt" ] && gen=()
    cmake -S . -B "$dir" "${gen[@]}" "${launcher[@]}" -DCMAKE_CXX_COMPILER=clang++ \
      -DCMAKE_BUILD_TYPE=Release -DVOX_SANITIZE=address,undefined,fuzzer-no-link -DVOX_FUZZ=ON \
      -DVOX_BUILD_BENCH=OFF
    if [ "${VOX_ASAN_SUITE:-ci}" = full ]; then
      # The whole default suite. python_module_test is left out: an instrumented
      # module cannot load into the uninstrumented python3 (the ASan runtime must
      # come first); the libraries it wraps are tested directly.
      cmake --build "$dir" -j "$jobs"
      ctest_args=(-LE long -E '^python_module_test$')
    else
      # CI's set (docs/robustness.md): the tests that have run clean under this
      # build within CI's time budget.
      tests=(storage_roundtrip_test storage_cache_test storage_corruption_test storage_writer_test
             storage_force_test storage_codec_test storage_memory_budget_test storage_info_test
             storage_brick_table_test storage_prefetch_test storage_lod_test
             storage_brick_limit_test storage_cache_stress_test core_fixed_point_test
             core_octree_test core_progress_test core_variants_test)
      cmake --build "$dir" -j "$jobs" --target "${tests[@]}"
      ctest_args=(-LE long -R "^($(IFS='|'; echo "${tests[*]}"))\$")
    fi
    (
      export ASAN_OPTIONS="detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=0:check_initialization_order=1:${ASAN_OPTIONS:-}"
      export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
      export LSAN_OPTIONS="suppressions=$PWD/scripts/sanitizer/lsan.supp:${LSAN_OPTIONS:-}"
      ctest --test-dir "$dir" --output-on-failure "${ctest_args[@]}" -j "$jobs" --timeout 1800
    )
    secs="${VOX_FUZZ_SECONDS:-25}"
    if [ "$secs" -gt 0 ]; then
      VOX_ASAN_DIR="$dir" scripts/fuzz.sh "${VOX_FUZZ_TARGETS:-store,parse}" "$secs"
    fi
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

#!/usr/bin/env bash
# Sanitizer builds and their tests (run by .ci/run after the normal suite).
# Which tests each stage runs is a ctest label set in each test's CMakeLists
# (docs/robustness.md lists the sets and why a test is left out):
#   scripts/sanitize.sh asan   ASan + UBSan build with clang in build-asan/ (every finding
#                              fatal). It also carries libFuzzer's coverage instrumentation
#                              (fuzzer-no-link), so the fuzz targets come from the same
#                              build. Builds and runs the tests labelled `asan`
#                              (VOX_ASAN_SUITE=full: everything but the benchmarks and the
#                              Python module, and every default test), then each libFuzzer target of
#                              VOX_FUZZ_TARGETS (default store,parse,exr,vdb) for
#                              VOX_FUZZ_SECONDS each (default 25; 0: none) through
#                              scripts/fuzz.sh.
#   scripts/sanitize.sh tsan   TSan build (gcc) in build-tsan/ of the tests labelled `tsan`
#                              (the threaded ones): builds their executables and runs them.
#                              vox's threads run on std::thread there, not TBB
#                              (VOX_PLAIN_THREADS, core/util/parallel.h), and the tests
#                              tsan_planted_race_{workers,pipeline} fail the stage unless
#                              TSan reports the race planted in those executors. The
#                              OpenVDB ingest tests stay out (docs/robustness.md).
# Tests that measure memory (RSS, cgroups) or tight time limits check
# VOX_SANITIZED and skip those checks: shadow memory and quarantine change
# what they measure.
# VOX_ASAN_DIR overrides the ASan build directory (also read by scripts/fuzz.sh).
# ctest's results go to DIR/ctest-junit.xml (.ci/run checks them for skips).
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-}"
jobs="${VOX_JOBS:-$(nproc)}"

# The build targets of the default tests carrying label $2 in build dir $1:
# each test's executable (ctest names it once built; before, the test's name,
# which vox_test gives its executable too) and any argument naming a built
# file (a test run through sh), kept if the build knows it.
label_targets() {
  local known
  known="$(cmake --build "$1" --target help | sed -n 's/^\(\.\.\. \)\{0,1\}\([A-Za-z0-9_.+-]*\):\{0,1\} .*$/\2/p')"
  ctest --test-dir "$1" -N -L "$2" -LE long --show-only=json-v1 | KNOWN="$known" python3 -c '
import json, os, sys
known = set(os.environ["KNOWN"].split())
names = set()
for t in json.load(sys.stdin)["tests"]:
    names.add(os.path.basename(t["command"][0]) if t.get("command") else t["name"])
    names.update(os.path.basename(a) for a in t.get("command", [])[1:])
print(" ".join(sorted(names & known)))'
}

case "$mode" in
  asan)
    dir="${VOX_ASAN_DIR:-build-asan}"
    scripts/sanitizer/configure.sh asan "$dir"
    if [ "${VOX_ASAN_SUITE:-ci}" = full ]; then
      cmake --build "$dir" -j "$jobs"
      labels=()
    else
      read -ra targets <<<"$(label_targets "$dir" asan)"
      # fuzz_seed_gen: the seed corpus the fuzz replays read (test fuzz_seeds);
      # vox-ingest: ingest_corrupt_chunk_test runs it by target name, which
      # ctest cannot report before it is built (label_targets misses it).
      cmake --build "$dir" -j "$jobs" --target "${targets[@]}" fuzz_seed_gen vox-ingest
      labels=(-L asan)
    fi
    (
      # exitcode=86: a report (ASan, UBSan, a leak) in a tool a test runs
      # must not pass for the tool's own error exit 1, which many tests
      # expect (a missing store, a corrupt file).
      export ASAN_OPTIONS="exitcode=86:detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=0:check_initialization_order=1:${ASAN_OPTIONS:-}"
      export UBSAN_OPTIONS="exitcode=86:print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
      export LSAN_OPTIONS="suppressions=$PWD/scripts/sanitizer/lsan.supp:${LSAN_OPTIONS:-}"
      ctest --test-dir "$dir" --output-on-failure "${labels[@]}" -LE long -j "$jobs" --timeout 1800 \
        --output-junit ctest-junit.xml
    )
    secs="${VOX_FUZZ_SECONDS:-25}"
    if [ "$secs" -gt 0 ]; then
      VOX_ASAN_DIR="$dir" scripts/fuzz.sh "${VOX_FUZZ_TARGETS:-store,parse,exr,vdb}" "$secs"
    fi
    ;;
  tsan)
    dir=build-tsan
    scripts/sanitizer/configure.sh tsan "$dir"
    read -ra targets <<<"$(label_targets "$dir" tsan)"
    cmake --build "$dir" -j "$jobs" --target "${targets[@]}"
    export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/scripts/sanitizer/tsan.supp:${TSAN_OPTIONS:-}"
    ctest --test-dir "$dir" --output-on-failure -L tsan -LE long -j "$jobs" --timeout 1800 \
      --output-junit ctest-junit.xml
    ;;
  *)
    echo "usage: scripts/sanitize.sh asan|tsan" >&2
    exit 2
    ;;
esac

#!/usr/bin/env bash
# Runs libFuzzer targets under ASan+UBSan for SECONDS each, with memory caps.
#   scripts/fuzz.sh TARGETS SECONDS     TARGETS: store | parse | exr | vdb, a comma list
#                                       of them (store,parse), or all
# Builds with clang into build-asan/ (VOX_ASAN_DIR overrides; the same build
# scripts/sanitize.sh asan makes, of which only what the targets need is
# built here), writes the seed corpus (fuzz_seed_gen) to DIR/fuzz/seeds/, and
# keeps what the fuzzer finds in DIR/fuzz/corpus/TARGET/ between runs. A
# crash leaves its input as DIR/fuzz/crash-* and fails the script; replay it
# with
#   build-asan/tests/fuzz/fuzz_TARGET build-asan/fuzz/crash-...
# CI runs `all` for 25 s each (scripts/sanitize.sh asan); a long run: scripts/fuzz.sh store 3600
# (docs/robustness.md).
set -euo pipefail
cd "$(dirname "$0")/.."
target="${1:-}"
secs="${2:-60}"
[ "$target" = all ] && target=store,parse,exr,vdb
IFS=, read -ra targets <<<"$target"
for t in "${targets[@]}"; do
  case "$t" in
    store|parse|exr|vdb) ;;
    *) echo "usage: scripts/fuzz.sh store|parse|exr|vdb[,...]|all SECONDS" >&2; exit 2 ;;
  esac
done
dir="${VOX_ASAN_DIR:-build-asan}"
scripts/sanitizer/configure.sh asan "$dir"
cmake --build "$dir" -j "${VOX_JOBS:-$(nproc)}" --target "${targets[@]/#/fuzz_}" fuzz_seed_gen
work="$dir/fuzz"
"$dir/tests/fuzz/fuzz_seed_gen" "$work/seeds" scripts/demo >/dev/null
export ASAN_OPTIONS="detect_leaks=1:${ASAN_OPTIONS:-}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
for t in "${targets[@]}"; do
  mkdir -p "$work/corpus/$t"
  t0=$SECONDS
  "$dir/tests/fuzz/fuzz_$t" -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=1024 \
    -timeout=20 -print_final_stats=1 -artifact_prefix="$work/" \
    "$work/corpus/$t" "$work/seeds/$t" 2>"$work/$t.log" || {
    tail -n 60 "$work/$t.log" >&2
    echo "fuzz: $t FAILED (log $work/$t.log, input $work/crash-* or timeout-*/oom-*)" >&2
    exit 1
  }
  # The last count is the fuzzer's own (vdb's forked children print theirs too).
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/$t.log" | grep -o '[0-9]*$' | tail -n 1 || echo "?")
  echo "fuzz: $t clean, $runs inputs in $((SECONDS - t0)) s"
done

#!/usr/bin/env bash
# Runs one libFuzzer target under ASan+UBSan for SECONDS with memory caps.
#   scripts/fuzz.sh TARGET SECONDS      TARGET: store | parse | exr | vdb
# Builds with clang into build-fuzz/ (only what the target needs), writes the
# seed corpus (fuzz_seed_gen) to build-fuzz/fuzz/seeds/, and keeps what the
# fuzzer finds in build-fuzz/fuzz/corpus/TARGET/ between runs. A crash leaves
# its input as build-fuzz/fuzz/crash-* and fails the script; replay it with
#   build-fuzz/tests/fuzz/fuzz_TARGET build-fuzz/fuzz/crash-...
# A long run: scripts/fuzz.sh store 3600 (docs/robustness.md).
set -euo pipefail
cd "$(dirname "$0")/.."
target="${1:-}"
secs="${2:-60}"
case "$target" in store|parse|exr|vdb) ;; *) echo "usage: scripts/fuzz.sh store|parse|exr|vdb SECONDS" >&2; exit 2;; esac
dir=build-fuzz
gen=()
command -v ninja >/dev/null && [ ! -f "$dir/CMakeCache.txt" ] && gen=(-G Ninja)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$dir" "${gen[@]}" "${launcher[@]}" -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_BUILD_TYPE=Release -DVOX_SANITIZE=address,undefined,fuzzer-no-link -DVOX_FUZZ=ON >/dev/null
cmake --build "$dir" -j "${VOX_JOBS:-$(nproc)}" --target "fuzz_$target" fuzz_seed_gen
work="$dir/fuzz"
mkdir -p "$work/corpus/$target"
"$dir/tests/fuzz/fuzz_seed_gen" "$work/seeds" scripts/demo >/dev/null
export ASAN_OPTIONS="detect_leaks=1:${ASAN_OPTIONS:-}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
"$dir/tests/fuzz/fuzz_$target" -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=1024 \
  -timeout=20 -print_final_stats=1 -artifact_prefix="$work/" \
  "$work/corpus/$target" "$work/seeds/$target"

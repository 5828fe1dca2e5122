#!/usr/bin/env bash
# Configures a sanitizer build directory; shared by scripts/sanitize.sh and
# scripts/fuzz.sh so both build the same objects in the same directory.
#   scripts/sanitizer/configure.sh asan DIR   clang, ASan + UBSan + libFuzzer's
#                                             coverage (fuzzer-no-link), fuzz targets on
#   scripts/sanitizer/configure.sh tsan DIR   gcc, TSan, vox's threads on std::thread
#                                             (VOX_PLAIN_THREADS: TSan cannot see into TBB)
# Both leave out the benchmarks and the Python module (an instrumented module
# cannot load into the uninstrumented python3; python_module_test then
# reports itself skipped).
set -euo pipefail
cd "$(dirname "$0")/../.."
mode="$1" dir="$2"
args=(-DCMAKE_BUILD_TYPE=Release -DVOX_BUILD_BENCH=OFF -DCMAKE_DISABLE_FIND_PACKAGE_pybind11=ON)
[ -f "$dir/CMakeCache.txt" ] || { command -v ninja >/dev/null && args+=(-G Ninja); }
command -v ccache >/dev/null && args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
case "$mode" in
  asan) args+=(-DCMAKE_CXX_COMPILER=clang++ -DVOX_SANITIZE=address,undefined,fuzzer-no-link
               -DVOX_FUZZ=ON) ;;
  tsan) args+=(-DVOX_SANITIZE=thread -DVOX_PLAIN_THREADS=ON) ;;
  *) echo "usage: scripts/sanitizer/configure.sh asan|tsan DIR" >&2; exit 2 ;;
esac
cmake -S . -B "$dir" "${args[@]}" >/dev/null

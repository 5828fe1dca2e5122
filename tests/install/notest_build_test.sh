#!/bin/sh
# -DBUILD_TESTING=OFF configures and builds the tools without GoogleTest,
# Google Benchmark or GMP: a fresh build tree WORK_DIR where finding GTest or
# benchmark is an error (CMAKE_DISABLE_FIND_PACKAGE_*) and GMP's pkg-config
# check must not run; every program is built and answers --version, and no
# test or benchmark program is built. Slow (a whole second build): ctest label
# `long`, or run it by hand.
#
#   notest_build_test.sh SOURCE_DIR WORK_DIR GENERATOR CXX_COMPILER LAUNCHER|none -- PROGRAM...
set -eu
src=$1 work=$2 generator=$3 cxx=$4
shift 4
launcher=$1
[ "$launcher" != none ] || launcher=""
shift 2  # LAUNCHER --
fail() { echo "notest_build_test: $*" >&2; exit 1; }

rm -rf "$work"
cmake -S "$src" -B "$work" -G "$generator" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_CXX_COMPILER="$cxx" ${launcher:+-DCMAKE_CXX_COMPILER_LAUNCHER="$launcher"} \
  -DBUILD_TESTING=OFF \
  -DCMAKE_DISABLE_FIND_PACKAGE_GTest=ON -DCMAKE_DISABLE_FIND_PACKAGE_benchmark=ON \
  >"$work.configure.log" 2>&1 || { cat "$work.configure.log" >&2; fail "configure failed"; }
if grep -E '^(GMPXX|GTest|benchmark)_' "$work/CMakeCache.txt" >&2; then
  fail "BUILD_TESTING=OFF still looked for GMP, GoogleTest or Google Benchmark"
fi
nice -n 10 cmake --build "$work" -j 2 >"$work.build.log" 2>&1 ||
  { tail -50 "$work.build.log" >&2; fail "build failed"; }
for p in "$@"; do
  "$work/tools/"*/"$p" --version || fail "$p not built or its --version failed"
done
if find "$work" -type f -perm -u+x \( -name '*_test' -o -name 'vox-*bench' -o -name 'fuzz_*' \) |
   grep . >&2; then
  fail "test or benchmark programs were built"
fi
[ ! -e "$work/CTestTestfile.cmake" ] || fail "BUILD_TESTING=OFF still registered tests"
rm -rf "$work" "$work.configure.log" "$work.build.log"
echo "notest_build_test: ok"

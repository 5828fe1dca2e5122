#!/usr/bin/env bash
# Configures and builds vox (Release) into build/, with the Python module in
# build/python/ (import with PYTHONPATH=build/python). Usage: scripts/build.sh [extra cmake args]
# VOX_TARGETS="a b" builds only those targets (scripts/demo.sh builds the three programs it runs).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
[ -f build/CMakeCache.txt ] && gen=()
cmake -S . -B build "${gen[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
targets=()
for t in ${VOX_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build build -j "$(nproc)" "${targets[@]}"

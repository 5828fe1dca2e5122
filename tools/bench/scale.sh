#!/usr/bin/env bash
# vox scale benchmark, one command: vox-render as the volume grows (vox-gen
# spheres of 1024^3, 2048^3, 4096^3 by default) and the memory limit shrinks
# (memory cgroups of 1/2, 1/4 and 1/8 of the store's size), full view and
# close-up, cold and warm; writes docs/scale.md and docs/scale.svg, raw rows
# in WORK/scale.csv (resumable: runs already there for the same vox-render
# binary are skipped, existing stores are reused).
#
#   tools/bench/scale.sh [--build build] [--work /tmp/vox-scale] [--grids 1024,2048,4096]
#                        [--limits 1/2,1/4,1/8] [--runs 3] [--threads 2] [--size 1024x1024]
#                        [--store-8192 PATH] [--vdb N=PATH]... [--timeout SECONDS]
#                        [--render-args "..."] [--no-cold] [--fresh] [--report-only]
#                        [--out docs/scale.md]
#   tools/bench/scale.sh --compare A.exr B.exr   # are two tiled EXRs' pixels identical?
#
# Run from the repository root as root (cold frames drop the page cache; the
# limited runs need a writable memory cgroup; without them they are skipped
# with a note). Long runs: --grids 8192 (generates a store of several GB) or
# --store-8192 PATH, and --grids 16384. Every option is described at the top
# of tools/bench/scale.py.
set -euo pipefail
exec python3 "$(dirname "$0")/scale.py" "$@"

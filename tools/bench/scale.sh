#!/usr/bin/env bash
# vox scale benchmark, one command: vox-render as the volume grows (vox-gen
# spheres or bumpy spheres, 1024^3, 2048^3, 4096^3 by default, or existing
# stores), in the default mode (level of detail) and exact (--lod 0), and the
# memory limit shrinks (memory cgroups of 1/2, 1/4 and 1/8 of the store's size,
# or one fixed --limit-mib), full view and close-up, cold and warm; writes
# docs/scale.md (with the scale law's table, ratios and docs/scale-law.svg) and
# docs/scale.svg, raw rows in WORK/scale.csv (resumable: runs already there for
# the same vox-render binary are skipped, existing stores are reused).
#
#   tools/bench/scale.sh [--build build] [--work DIR] [--grids 1024,2048,4096]
#                        [--shapes sphere,bumpy] [--modes default,exact]
#                        [--limits 1/2,1/4,1/8 | --limit-mib 512] [--runs 3] [--threads 2]
#                        [--size 1024x1024] [--store SHAPE:N=PATH]... [--store-8192 PATH]
#                        [--vdb N=PATH]... [--timeout SECONDS]
#                        [--render-args "..."] [--no-cold] [--fresh] [--report-only]
#                        [--out docs/scale.md]
#   tools/bench/scale.sh --compare A.exr B.exr   # are two tiled EXRs' pixels identical?
#
# The scale law, e.g. on existing stores:
#   nice -n 19 tools/bench/scale.sh --grids 4096,8192,16384,32768 --shapes sphere,bumpy \
#       --modes default,exact --limit-mib 512 --runs 1 \
#       --store sphere:4096=/data/sphere4096.store --store bumpy:4096=/data/bumpy4096.store ...
#
# Run from the repository root as root (cold frames drop the page cache; the
# limited runs need a writable memory cgroup; without them they are skipped
# with a note). Every option is described at the top of tools/bench/scale.py.
set -euo pipefail
exec python3 "$(dirname "$0")/scale.py" "$@"

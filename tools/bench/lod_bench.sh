#!/usr/bin/env bash
# lod_bench.sh BUILD_DIR STORE CAM.json OUT_DIR [RUNS] [THREADS]: vox-render with LOD off and
# with --lod 1, side by side (alternating), RUNS times cold (page cache dropped before each run:
# needs root) and RUNS times warm; prints one line per run and the medians, then compares the
# last images with vox-lod-compare (docs/lod.md).
set -euo pipefail
b=$(realpath "$1"); store=$2; cam=$3; out=$4; runs=${5:-3}; threads=${6:-2}
mkdir -p "$out"
R="$b/tools/render/vox-render"; C="$b/tools/bench/vox-lod-compare"
run() {  # mode temp tag
  local mode=$1 temp=$2 tag=$3 extra=""
  [ "$mode" = lod ] && extra="--lod 1"
  [ "$temp" = cold ] && { sync; echo 3 > /proc/sys/vm/drop_caches; }
  "$R" "$store" --cam "$cam" --threads "$threads" -o "$out/$mode.exr" --stats "$out/$mode-$temp-$tag.json" --quiet $extra
  python3 - "$out/$mode-$temp-$tag.json" "$mode" "$temp" <<'EOF'
import json, sys
j = json.load(open(sys.argv[1]))
lod = j.get("lod")
bricks = lod["bricks_paged_total"] if lod else j["cache"]["bricks_paged_in"]
brick_bytes = lod["brick_bytes_read_total"] if lod else j["io"]["brick_bytes_read"]
print(f'{sys.argv[2]:4} {sys.argv[3]:4} bricks {bricks:7d} brick_bytes {brick_bytes:11d} '
      f'read_bytes {j["io"]["read_bytes"]:11d} render_s {j["timings"]["render_seconds"]:8.3f} '
      f'total_s {j["timings"]["total_seconds"]:8.3f}')
EOF
}
for temp in cold warm; do
  [ "$temp" = warm ] && { run off warm pre >/dev/null; run lod warm pre >/dev/null; }
  for i in $(seq 1 "$runs"); do run off "$temp" "$i"; run lod "$temp" "$i"; done
done | tee "$out/runs.txt"
python3 - "$out/runs.txt" <<'EOF'
import sys, statistics
rows = [l.split() for l in open(sys.argv[1])]
for mode in ("off", "lod"):
    for temp in ("cold", "warm"):
        r = [x for x in rows if x[0] == mode and x[1] == temp]
        if not r: continue
        med = lambda k: statistics.median(float(x[x.index(k) + 1]) for x in r)
        print(f"median {mode} {temp}: bricks {med('bricks'):.0f} brick_bytes {med('brick_bytes'):.0f} "
              f"read_bytes {med('read_bytes'):.0f} render_s {med('render_s'):.3f} total_s {med('total_s'):.3f}")
EOF
"$C" "$out/off.exr" "$out/lod.exr"

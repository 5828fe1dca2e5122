#!/usr/bin/env bash
# vox-render vs OpenVDB's vdb_render, side by side on the same level set,
# camera, image size and thread count.
#
#   tools/bench/render_bench.sh [BUILD_DIR] [WORK_DIR]
#
# Makes `vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3` (if WORK_DIR lacks
# it), ingests it with vox-ingest, then times RUNS (default 5) frames of each
# at WIDTHxHEIGHT (default 1024x1024) with THREADS (default 2):
#   vox:  vox-render-bench in one process: the first frame with an empty brick
#         cache (cold), the others warm; like vdb_render's ray-tracing time,
#         without the EXR write (BENCH_EXR=1 includes it).
#   vdb:  vdb_render -shader diffuse -v, its "ray-tracing" time; CPU seconds
#         are the run's CPU minus that of an 8x8 run (load and write only).
# Prints medians, rays/s, DDA moves/s and the ratios, wall clock and CPU (on a
# loaded machine the CPU ratio is the fairer one).
set -euo pipefail
build=${1:-build}
work=${2:-/tmp/vox-render-bench}
runs=${RUNS:-5}
threads=${THREADS:-2}
res=${WIDTH:-1024}x${HEIGHT:-1024}
w=${res%x*} h=${res#*x}
mkdir -p "$work"
vdb="$work/sphere2048.vdb" store="$work/sphere2048.store"
if [[ ! -f $vdb ]]; then
  vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3 -write "$vdb" >/dev/null
fi
if [[ ! -d $store ]]; then
  "$build/tools/ingest/vox-ingest" "$vdb" "$store" --quiet --force
fi
cat >"$work/cam.json" <<JSON
{"position":[0,0,3], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40, "width":$w, "height":$h, "projection":"perspective"}
JSON
# vdb_render's diffuse shader: one directional light, no shadows.
cat >"$work/scene.json" <<JSON
{"lights":[{"type":"directional","direction":[-0.3,-0.5,-1],"shadows":false}], "material":{"specular":0}}
JSON
"$build/tools/bench/vox-render-bench" "$store" --cam "$work/cam.json" --scene "$work/scene.json" \
  --runs "$((runs + 1))" --threads "$threads" ${BENCH_EXR:+--exr "$work/vox.exr"} >"$work/vox.json"
cpu() { /usr/bin/time -f "%U %S" "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1 + $2}'; }
base_cpu=$(cpu vdb_render "$vdb" "$work/vdb_small.exr" -translate 0,0,3 -lookat 0,0,0 -fov 40 -res 8x8 -cpus "$threads")
: >"$work/vdb.txt"
for ((i = 0; i < runs; ++i)); do
  out=$( { /usr/bin/time -f "CPU %U %S" vdb_render "$vdb" "$work/vdb.exr" -translate 0,0,3 -lookat 0,0,0 -up 0,1,0 \
           -fov 40 -res "$res" -cpus "$threads" -shader diffuse -v; } 2>&1 )
  wall=$(echo "$out" | grep -A1 "ray-tracing" | grep -o "completed in [0-9.]* sec" | grep -o "[0-9.]*" | head -1)
  c=$(echo "$out" | grep "^CPU" | awk '{print $2 + $3}')
  echo "$wall $c" >>"$work/vdb.txt"
done
python3 - "$work" "$base_cpu" <<'PY'
import json, statistics, sys
work, base = sys.argv[1], float(sys.argv[2])
v = json.load(open(f"{work}/vox.json"))
rows = [l.split() for l in open(f"{work}/vdb.txt") if l.strip()]
vdb_wall = statistics.median(float(r[0]) for r in rows)
vdb_cpu = statistics.median(float(r[1]) - base for r in rows)
print(f"image {v['width']}x{v['height']}, {v['threads']} threads, split {v['split']}, passes {v['passes']}")
print(f"vox-render  cold {v['cold_seconds']:.3f} s wall ({v['cold_cpu_seconds']:.3f} s CPU); "
      f"warm median {v['warm_median_seconds']:.3f} s wall ({v['warm_cpu_median_seconds']:.3f} s CPU) "
      f"over {len(v['warm_seconds'])} frames")
print(f"            {v['warm_rays_per_second']/1e6:.2f} M rays/s, {v['warm_dda_moves_per_second']/1e6:.1f} M DDA moves/s (warm, wall); "
      f"per CPU second {v['rays']/v['warm_cpu_median_seconds']/1e6:.2f} M rays, {v['dda_moves']/v['warm_cpu_median_seconds']/1e6:.1f} M moves")
print(f"vdb_render  median {vdb_wall:.3f} s wall ray-tracing, {vdb_cpu:.3f} s CPU over {len(rows)} runs")
print(f"speed-up    warm {vdb_wall / v['warm_median_seconds']:.2f}x wall, {vdb_cpu / v['warm_cpu_median_seconds']:.2f}x CPU; "
      f"cold {vdb_wall / v['cold_seconds']:.2f}x wall, {vdb_cpu / v['cold_cpu_seconds']:.2f}x CPU")
PY

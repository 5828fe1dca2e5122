#!/usr/bin/env bash
# whole.sh BUILD_DIR SCRATCH_DIR: whole processes (open, render, write the
# EXR, exit) of vox-render and OpenVDB's vdb_render, side by side on the
# 2048^3 sphere (`vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3`, made in
# SCRATCH_DIR with its store if missing, as peer.sh does), camera (0,0,3)
# fov 40, one directional light without shadows (vdb_render -shader diffuse),
# SIZE^2 pixels (1024), THREADS (2). RUNS (7) rounds, each one run of each,
# alternately; prints medians of the wall times, their ratio, and vox's EXR
# write share (--stats: write seconds summed over threads / (threads x render
# seconds)). VOX_FLAGS adds vox-render flags (e.g. "--float", "--compression none").
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: whole.sh BUILD_DIR SCRATCH_DIR" >&2; exit 2; }
b=$(realpath "$1")
mkdir -p "$2"
d=$(realpath "$2")
runs=${RUNS:-7} threads=${THREADS:-2} size=${SIZE:-1024}
if [ ! -s "$d/sphere.vdb" ]; then
  vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3 -write "$d/sphere.vdb.tmp.vdb" >/dev/null
  mv "$d/sphere.vdb.tmp.vdb" "$d/sphere.vdb"
fi
[ -d "$d/sphere.store" ] || "$b/tools/ingest/vox-ingest" "$d/sphere.vdb" "$d/sphere.store" --force --quiet
cat >"$d/whole.cam.json" <<JSON
{"position":[0,0,3], "look_at":[0,0,0], "up":[0,1,0], "fov_deg":40, "width":$size, "height":$size}
JSON
cat >"$d/whole.scene.json" <<JSON
{"lights":[{"type":"directional","direction":[-0.3,-0.5,-1],"shadows":false}], "material":{"specular":0}}
JSON
: >"$d/whole.txt"
wall() { /usr/bin/time -f "%e" "$@" 2>&1 >/dev/null | tail -1; }
for ((i = 0; i < runs; ++i)); do
  # shellcheck disable=SC2086
  v=$(wall "$b/tools/render/vox-render" "$d/sphere.store" --cam "$d/whole.cam.json" \
        --scene "$d/whole.scene.json" -o "$d/whole-vox.exr" --threads "$threads" --quiet \
        --stats "$d/whole-stats.json" ${VOX_FLAGS:-})
  share=$(python3 -c "import json,sys; t=json.load(open(sys.argv[1]))['timings']; print(t['write_seconds'] / ($threads * t['render_seconds']), t['render_seconds'], t['open_seconds'] + t['setup_seconds'])" "$d/whole-stats.json")
  o=$(wall vdb_render "$d/sphere.vdb" "$d/whole-vdb.exr" -translate 0,0,3 -lookat 0,0,0 -up 0,1,0 \
        -fov 40 -res "${size}x${size}" -cpus "$threads" -shader diffuse)
  echo "$v $o $share" | tee -a "$d/whole.txt"
done
python3 - "$d/whole.txt" "$d/whole-vox.exr" <<'PY'
import os, statistics as st, sys
rows = [list(map(float, l.split())) for l in open(sys.argv[1]) if l.strip()]
vox, vdb = st.median(r[0] for r in rows), st.median(r[1] for r in rows)
share, render, setup = (st.median(r[i] for r in rows) for i in (2, 3, 4))
print(f"whole process, median of {len(rows)}: vox-render {vox:.3f} s, vdb_render {vdb:.3f} s: "
      f"{vdb / vox:.2f}x; vox frame {render:.3f} s, EXR write {100 * share:.1f}% of the threads' "
      f"frame time, open + set-up {setup:.3f} s, EXR {os.path.getsize(sys.argv[2]) / 1e6:.1f} MB")
PY

#!/usr/bin/env bash
# peer.sh BUILD_DIR SCRATCH_DIR [SCENES]: vox against NanoVDB's CPU ray caster
# (vox-peer-bench) on the peer scenes of docs/performance.md, each seen by two
# cameras: a full view (the whole object) and a close view (the object fills
# at least half the frame: checked, the run fails otherwise). Makes each
# scene's level set (.vdb, with vdb_tool), its vox store (vox-ingest) and
# cameras in SCRATCH_DIR once (kept for later runs), runs vox-peer-bench on
# each camera, keeps its JSON in SCRATCH_DIR/NAME.VIEW.json, and prints a
# table: vox's frame against NanoVDB's shaded frame and against its bare loop,
# medians of the alternated rounds and best frames.
#   SCENES: comma-separated subset of sphere,bunny,dodecahedron (default all)
#   env ROUNDS (default 7), THREADS (2), SIZE (1024), BUNNY (the bunny's PLY),
#       PEER_FLAGS (more vox-peer-bench flags, e.g. "--no-clip")
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: peer.sh BUILD_DIR SCRATCH_DIR [sphere,bunny,dodecahedron]" >&2; exit 2; }
b=$(realpath "$1")
mkdir -p "$2"
d=$(realpath "$2")
scenes=${3:-sphere,bunny,dodecahedron}
rounds=${ROUNDS:-7}
threads=${THREADS:-2}
size=${SIZE:-1024}
bunny_ply=${BUNNY:-/work/shared/data/stanford-bunny/bunny.ply}
ingest=$b/tools/ingest/vox-ingest
bench=$b/tools/bench/vox-peer-bench
for t in "$ingest" "$bench"; do [ -x "$t" ] || { echo "peer.sh: $t not built" >&2; exit 1; }; done
command -v vdb_tool >/dev/null || { echo "peer.sh: vdb_tool not installed (libopenvdb-tools)" >&2; exit 1; }

# make NAME VDB_TOOL_ARGS... : the scene's .vdb and store, unless present.
make_scene() {
  local name=$1; shift
  if [ ! -s "$d/$name.vdb" ]; then
    echo "peer.sh: making $name.vdb: vdb_tool $* -write $name.vdb" >&2
    vdb_tool "$@" -write "$d/$name.vdb.tmp.vdb" >/dev/null
    mv "$d/$name.vdb.tmp.vdb" "$d/$name.vdb"
  fi
  if [ ! -d "$d/$name.store" ]; then
    "$ingest" "$d/$name.vdb" "$d/$name.store" --force --quiet
  fi
}

# camera NAME.VIEW POSITION LOOK_AT FOV
camera() {
  printf '{"position":[%s], "look_at":[%s], "up":[0,1,0], "fov_deg":%s, "width":%d, "height":%d}\n' \
    "$2" "$3" "$4" "$size" "$size" >"$d/$1.cam.json"
}

IFS=, read -ra list <<<"$scenes"
runs=()
for s in "${list[@]}"; do
  case $s in
    sphere)
      make_scene sphere -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3
      camera sphere.full 0,0,3 0,0,0 40
      camera sphere.close 0.55,0.35,1.45 0.3,0.2,0 40 ;;
    bunny)
      [ -r "$bunny_ply" ] || { echo "peer.sh: $bunny_ply not found (set BUNNY)" >&2; exit 1; }
      # The scan has holes at its base: build the level set from its points.
      make_scene bunny -read "$bunny_ply" -points2ls d=300 r=1.5 w=3 -dilate r=1 -erode r=1
      camera bunny.full -0.017,0.11,0.35 -0.017,0.11,0 44.8
      camera bunny.close -0.03,0.1,0.17 -0.03,0.1,0 44.8 ;;
    dodecahedron)
      make_scene dodecahedron -platonic d=1024 f=12 s=1 w=3
      camera dodecahedron.full 0,0,3 0,0,0 40
      camera dodecahedron.close 0.2,0.3,1.5 0,0,0 40 ;;
    *) echo "peer.sh: unknown scene '$s' (sphere, bunny, dodecahedron)" >&2; exit 2 ;;
  esac
  for view in full close; do
    echo "== $s $view: vox-peer-bench $d/$s.vdb --store $d/$s.store --cam $d/$s.$view.cam.json --rounds $rounds --threads $threads ${PEER_FLAGS:-}" >&2
    # shellcheck disable=SC2086
    "$bench" "$d/$s.vdb" --store "$d/$s.store" --cam "$d/$s.$view.cam.json" --rounds "$rounds" \
      --threads "$threads" ${PEER_FLAGS:-} >"$d/$s.$view.json"
    runs+=("$d/$s.$view.json")
  done
done
python3 - "${runs[@]}" <<'PY'
import json, os, sys
print("| scene | view | hit pixels | vox/NanoVDB frame (median, best) | vox/NanoVDB bare loop (median, best) |")
print("| --- | --- | --- | --- | --- |")
bad = []
for path in sys.argv[1:]:
    j = json.load(open(path))
    scene, view = os.path.basename(path).split(".")[:2]
    hits = 1.0 - j["check"]["miss_fraction"]
    if view == "close" and hits < 0.5:
        bad.append("%s: the close view's object fills %.0f%% of the frame, not half" % (path, 100 * hits))
    print("| %s | %s | %.0f%% | %.2fx, %.2fx | %.2fx, %.2fx |" % (
        scene, view, 100 * hits, j["vox_over_nano_frame"], j["vox_over_nano_frame_best"],
        j["vox_over_nano_bare"], j["vox_over_nano_bare_best"]))
for b in bad:
    print("peer.sh: " + b, file=sys.stderr)
sys.exit(1 if bad else 0)
PY

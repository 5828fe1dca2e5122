#!/usr/bin/env bash
# peer.sh BUILD_DIR SCRATCH_DIR [SCENES]: vox against NanoVDB's CPU ray caster
# (vox-peer-bench) on the peer scenes of docs/benchmarks.md. Makes each scene's
# level set (.vdb, with vdb_tool), its vox store (vox-ingest) and camera in
# SCRATCH_DIR once (kept for later runs), then runs vox-peer-bench on it and
# keeps its JSON in SCRATCH_DIR/NAME.json.
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

# camera NAME POSITION LOOK_AT FOV
camera() {
  printf '{"position":[%s], "look_at":[%s], "up":[0,1,0], "fov_deg":%s, "width":%d, "height":%d}\n' \
    "$2" "$3" "$4" "$size" "$size" >"$d/$1.cam.json"
}

IFS=, read -ra list <<<"$scenes"
for s in "${list[@]}"; do
  case $s in
    sphere)
      make_scene sphere -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3
      camera sphere 0,0,3 0,0,0 40 ;;
    bunny)
      [ -r "$bunny_ply" ] || { echo "peer.sh: $bunny_ply not found (set BUNNY)" >&2; exit 1; }
      # The scan has holes at its base: build the level set from its points.
      make_scene bunny -read "$bunny_ply" -points2ls d=300 r=1.5 w=3 -dilate r=1 -erode r=1
      camera bunny -0.017,0.11,0.35 -0.017,0.11,0 44.8 ;;
    dodecahedron)
      make_scene dodecahedron -platonic d=1024 f=12 s=1 w=3
      camera dodecahedron 0,0,3 0,0,0 40 ;;
    *) echo "peer.sh: unknown scene '$s' (sphere, bunny, dodecahedron)" >&2; exit 2 ;;
  esac
  echo "== $s: vox-peer-bench $d/$s.vdb --store $d/$s.store --cam $d/$s.cam.json --rounds $rounds --threads $threads ${PEER_FLAGS:-}" >&2
  # shellcheck disable=SC2086
  "$bench" "$d/$s.vdb" --store "$d/$s.store" --cam "$d/$s.cam.json" --rounds "$rounds" \
    --threads "$threads" ${PEER_FLAGS:-} | tee "$d/$s.json"
done

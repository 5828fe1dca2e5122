#!/usr/bin/env bash
# The README's first command: installs what vox needs, builds the three
# programs the demo runs (vox-ingest, vox-info, vox-render; scripts/test.sh
# builds the rest), and runs them on the built-in demo scene: a level set made
# with OpenVDB's vdb_tool, ingested into a store and rendered to out/demo.exr
# and out/demo.png.
set -euo pipefail
cd "$(dirname "$0")/.."
VOX_TARGETS="vox-ingest vox-info vox-render" scripts/build.sh
mkdir -p out
bin=build/tools
if [ ! -s out/demo.vdb ]; then
  # A dodecahedron and a sphere: shading, shadows, a reflective sphere.
  vdb_tool -platonic f=12 s=0.45 c=-0.45,0.0,0.0 v=0.002 w=3 \
           -sphere r=0.3 c=0.45,-0.1,0.1 v=0.002 w=3 \
           -union -write out/demo.vdb >/dev/null
fi
"$bin"/ingest/vox-ingest out/demo.vdb out/demo.store --force
"$bin"/info/vox-info out/demo.store
"$bin"/render/vox-render out/demo.store --cam scripts/demo/cam.json --scene scripts/demo/scene.json \
    -o out/demo.exr --preview out/demo.png --stats out/demo-stats.json
echo "demo: wrote out/demo.exr and out/demo.png (stats: out/demo-stats.json)"

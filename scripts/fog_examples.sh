#!/bin/sh
# The example pictures of docs/fog.md: fog controls on a fog sphere.
#
#   scripts/fog_examples.sh BUILD_DIR WORK_DIR [OUT_DIR]
#
# Makes fire.vdb with vdb_tool: a grid "density" (a sphere of radius 1,
# voxels of 0.025, -ls2fog of a level set 20 voxels wide: density 0 at the
# surface rising to 1 half a unit in) and a grid "temperature" (the same
# made of a sphere of radius 0.7), ingests it with
# `vox-ingest --grid density --temperature temperature`, writes one scene
# per control into WORK_DIR and renders each at 200x200 with vox-render's
# default camera, writing OUT_DIR/NAME.png (default OUT_DIR: docs/fog).
# Needs vdb_tool and BUILD_DIR's vox-ingest and vox-render.
set -eu
build=$(cd "$1" && pwd)
work=$2
out=${3:-$(dirname "$0")/../docs/fog}
mkdir -p "$work" "$out"
out=$(cd "$out" && pwd)
cd "$work"
if [ ! -f fire.vdb ]; then
  vdb_tool -sphere r=1.0 voxel=0.025 width=20 name=outer -ls2fog name=density \
           -sphere r=0.7 voxel=0.025 width=20 name=inner -ls2fog name=temperature \
           -write codec=blosc fire.vdb
fi
if [ ! -d fire ]; then
  "$build/tools/ingest/vox-ingest" fire.vdb fire --grid density --temperature temperature --quiet
fi
light='"lights":[{"type":"directional","direction":[-0.5,-1,-0.6],"intensity":1.5}]'
back='"lights":[{"type":"directional","direction":[0.45,0.35,0.8],"intensity":0.35}]'
scene() {  # NAME LIGHTS VOLUME
  printf '{%s, "background":[0.02,0.02,0.03], "volume":{%s}}\n' "$2" "$3" > "$1.json"
}
scene grey "$light" '"absorption":1, "scattering":4'
scene rgb "$light" '"absorption":[0.5,1.5,3], "scattering":[4,3,2]'
scene ramp "$light" '"absorption":1, "scattering":4, "ramp":[
  {"density":0.0, "color":[0.2,0.4,1.0], "opacity":0},
  {"density":0.3, "color":[1.0,1.0,1.0], "opacity":1},
  {"density":0.6, "color":[1.0,0.5,0.1], "opacity":8}]'
scene emission '"lights":[]' '"absorption":2, "scattering":0,
  "emission":{"color":[0.3,0.8,1.0], "intensity":1.5}'
scene blackbody "$light" '"absorption":1, "scattering":2, "color":[0.3,0.3,0.3],
  "blackbody":{"intensity":4, "kelvin_scale":1500, "kelvin_offset":1500, "reference_kelvin":3000}'
scene phase_iso "$back" '"absorption":0.5, "scattering":3'
scene phase_forward "$back" '"absorption":0.5, "scattering":3, "phase_g":0.7'
for name in grey rgb ramp emission blackbody phase_iso phase_forward; do
  "$build/tools/render/vox-render" fire --scene "$name.json" --size 200x200 \
    -o "$name.exr" --preview "$out/$name.png" --quiet
  echo "$out/$name.png"
done

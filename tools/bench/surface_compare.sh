#!/bin/sh
# A level-set close-up: vox's default image against vdb_render's.
#
#   tools/bench/surface_compare.sh BUILD_DIR WORK_DIR BUNNY_PLY [EXTRA_SCENE_FIELDS]
#
# Makes the Stanford bunny's level set with vdb_tool (as docs/performance.md's
# peers: -points2ls d=300 r=1.5 w=3 -dilate r=1 -erode r=1), ingests it and
# renders a close-up of its head (512x512, fov 40) twice: vdb_render
# -shader diffuse, and vox-render with the same camera and vdb_render's
# lighting (a light at the eye, no falloff, no ambient, no specular, no
# shadows) plus EXTRA_SCENE_FIELDS (e.g. '"normals":"flat"'). Prints
# vox-surface-compare's figures: each image's mask (vox: alpha > 1/2;
# vdb_render: its -shader matte image, white where it hits), their IoU,
# and the RMSE of RGB over the pixels both cover. Writes the images' PNGs
# (vdb.png, vox.png) in WORK_DIR. Needs vdb_tool, vdb_render and BUILD_DIR's
# vox-ingest, vox-render and vox-surface-compare.
set -eu
build=$(cd "$1" && pwd)
work=$2
ply=$(cd "$(dirname "$3")" && pwd)/$(basename "$3")
extra=${4:-}
mkdir -p "$work"
cd "$work"
eye='-0.03,0.14,0.12'
at='-0.045,0.125,0.03'
if [ ! -f bunny300.vdb ]; then
  vdb_tool -read "$ply" -points2ls d=300 r=1.5 w=3 -dilate r=1 -erode r=1 \
    -write bunny300.vdb >/dev/null
fi
if [ ! -d bunny_store ]; then
  "$build/tools/ingest/vox-ingest" bunny300.vdb bunny_store --quiet
fi
printf '{"position":[%s], "look_at":[%s], "up":[0,1,0], "fov_deg":40, "width":512, "height":512}\n' \
  "$eye" "$at" >cam.json
sep=''
[ -n "$extra" ] && sep=', '
printf '{"background":[0,0,0], "ambient":[0,0,0], "lights":[{"type":"point", "position":[%s], "falloff":"none", "shadows":false}], "material":{"color":[1,1,1], "diffuse":1, "specular":0}%s%s}\n' \
  "$eye" "$sep" "$extra" >scene.json
"$build/tools/render/vox-render" bunny_store --cam cam.json --scene scene.json -o vox.exr \
  --preview vox.png --quiet
for out in vdb.exr vdb.png vdb_mask.exr; do
  shader=diffuse
  [ "$out" = vdb_mask.exr ] && shader=matte  # white where it hits: the mask
  vdb_render bunny300.vdb "$out" -translate "$eye" -lookat "$at" -up 0,1,0 -fov 40 \
    -res 512x512 -shader "$shader" -cpus 2 >/dev/null
done
"$build/tools/bench/vox-surface-compare" vdb.exr vox.exr vdb_mask.exr

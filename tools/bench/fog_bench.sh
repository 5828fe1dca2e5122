#!/bin/sh
# Shadowed fog: vox against vdb_render, and vox's quality against its own
# converged image.
#
#   tools/bench/fog_bench.sh BUILD_DIR WORK_DIR [REPEATS]
#
# Makes two fog volumes with vdb_tool (a sphere, 249^3, and a dodecahedron:
# -platonic f=12 s=1.0 v=0.006 w=3, each -ls2fog), ingests them, and renders
# each with one directional light with shadows, one thread, at 256x256 and
# 320x240, from vox's default camera (vdb_render gets the same position,
# look-at, up and horizontal fov, and the light with a colour: without one
# its image is black). Per frame it prints:
#   - vox's default frame and vdb_render, alternately, REPEATS times (3),
#     whole-process medians: CPU seconds (user + sys: fair on a shared
#     machine) and wall seconds, and their ratio: each with its default
#     medium, then both with vdb_render's (absorption 0.1 and scattering 1.5
#     per voxel: vox gets them per world unit; vox also at light_optical_depth
#     0.1), then both with vox's (0.5 and 0.5 per world unit: vdb_render gets
#     them per voxel, without its shadow "gain", which thins the medium along
#     shadow rays);
#   - the RMSE of vox's image against vox's converged image of that medium
#     (exact voxels, exact transmittance rays, the light every half voxel and
#     at most 0.01 optical depth apart, float EXR), as a percentage of the
#     converged image's mean over all pixels;
#   - the time-against-RMSE curve: vox at other settings of the scene's
#     "volume" quality fields (render/scene.h), one run each;
#   - the sphere lit along x, from above and as vdb_render's default light
#     is (towards 0.3,0.3,0): vox's default, without the light's lattice,
#     at light_optical_depth 0.05 and exact (--lod 0), against its
#     converged image of that light.
# Needs vdb_tool, vdb_render and BUILD_DIR's vox-ingest, vox-render and
# vox-lod-compare. The converged images take minutes.
set -eu
build=$(cd "$1" && pwd)
work=$2
repeats=${3:-3}
mkdir -p "$work"
cd "$work"
render=$build/tools/render/vox-render
compare=$build/tools/bench/vox-lod-compare
light_dir='-1,-1,-1'  # vox: the way the light travels; vdb_render: towards the light

scene() {  # scene.json with the volume fields $1
  printf '{"lights":[{"type":"directional","direction":[%s],"color":[1,1,1],"intensity":1,"shadows":true}], "volume":{%s}}\n' \
    "$light_dir" "$1"
}

cpu_wall() {  # runs "$@", prints "cpu wall" seconds of the whole process
  # (the child's rusage in microseconds: GNU time's %U and %S round to
  # 10 ms, a twentieth of these frames)
  python3 -c '
import resource, subprocess, sys, time
def cpu():  # (children reaped before, e.g. by a launcher script, excluded)
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime
c, w = cpu(), time.monotonic()
subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
print("%.4f %.4f" % (cpu() - c, time.monotonic() - w))' "$@"
}

median() { sort -n | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }

rmse_pct() {  # RMSE of $2 against reference $1, % of $1's mean (black: $3)
  mean=$("$compare" "$1" "$3" | sed 's/.*"mean_abs_rgb": \([0-9.e-]*\).*/\1/')
  "$compare" "$1" "$2" | sed 's/.*"rmse_rgb": \([0-9.e-]*\).*/\1/' |
    awk -v m="$mean" '{ printf "%.3f", 100 * $1 / m }'
}

race() {  # label vox-command vdb_render-command [REF]: alternate runs, print a table row
  # (with REF, vox's image's RMSE against that converged image; else "-")
  : >vox_times.txt
  : >vdb_times.txt
  i=0
  while [ "$i" -lt "$repeats" ]; do
    rm -f "vox_$name.exr"
    cpu_wall $2 --float -o "vox_$name.exr" >>vox_times.txt
    cpu_wall $3 >>vdb_times.txt
    i=$((i + 1))
  done
  vc=$(cut -d' ' -f1 vox_times.txt | median) vw=$(cut -d' ' -f2 vox_times.txt | median)
  dc=$(cut -d' ' -f1 vdb_times.txt | median) dw=$(cut -d' ' -f2 vdb_times.txt | median)
  r=-
  [ -n "${4:-}" ] && r=$(rmse_pct "$4" "vox_$name.exr" "black_$name.exr")
  echo "| $1 | $vc | $vw | $dc | $dw | $(echo "$vc $dc" | awk '{ printf "%.2f", $1 / $2 }') | $r |"
}

frame() {  # name vdb_tool-args WxH
  name=$1 size=$3
  w=${size%x*} h=${size#*x}
  [ -f "$name.vdb" ] || vdb_tool $2 -ls2fog -write "$name.vdb" >/dev/null
  [ -d "$name.vox" ] || "$build/tools/ingest/vox-ingest" "$name.vdb" "$name.vox" --quiet
  scene "" >scene.json
  rm -f cam.exr
  "$render" "$name.vox" -o cam.exr --size 16x16 --save-cam "cam16_$name.json" --scene scene.json --quiet
  sed "s/\"width\":16/\"width\":$w/; s/\"height\":16/\"height\":$h/" "cam16_$name.json" >"cam_$name.json"
  pos=$(sed 's/.*"position":\[\([^]]*\)\].*/\1/' "cam_$name.json")
  at=$(sed 's/.*"look_at":\[\([^]]*\)\].*/\1/' "cam_$name.json")
  up=$(sed 's/.*"up":\[\([^]]*\)\].*/\1/' "cam_$name.json")
  fov=$(sed 's/.*"fov_deg":\([0-9.]*\).*/\1/' "cam_$name.json")
  vox="$render $name.vox --cam cam_$name.json --threads 1 --quiet"
  # The converged image, and an empty one (the camera turned away) for the mean.
  if [ ! -f "ref_$name.exr" ]; then
    scene '"light_step":0.5, "light_optical_depth":0.01, "shadow_lod":0' >ref_scene.json
    $render "$name.vox" --cam "cam_$name.json" --scene ref_scene.json --threads 1 --quiet --lod 0 \
      --float -o "ref_$name.exr"
  fi
  sed 's/"position":\[[^]]*\]/"position":[0,0,1e3]/; s/"look_at":\[[^]]*\]/"look_at":[0,0,2e3]/' \
    "cam_$name.json" >"black_$name.json"
  rm -f "black_$name.exr"
  $render "$name.vox" --cam "black_$name.json" --scene scene.json --quiet --float -o "black_$name.exr"
  vdb="vdb_render $name.vdb vdb_$name.ppm -res ${w}x$h -translate $pos -lookat $at -up $up -fov $fov \
    -light 1,1,1,1,1,1 -cpus 1"
  race "$name $size" "$vox --scene scene.json" "$vdb" "ref_$name.exr"
  # The same medium for both: vdb_render's coefficients are per voxel step.
  vs=$("$build/tools/info/vox-info" "$name.vox" | sed -n 's/^ *voxel size: *//p')
  thick=$(echo "$vs" | awk '{ printf "%.6g, \"scattering\":%.6g", 0.1 / $1, 1.5 / $1 }')
  scene "\"absorption\":$thick" >thick_scene.json
  if [ ! -f "ref_thick_$name.exr" ]; then
    scene "\"absorption\":$thick, \"light_step\":0.5, \"light_optical_depth\":0.01, \"shadow_lod\":0" \
      >ref_thick_scene.json
    $render "$name.vox" --cam "cam_$name.json" --scene ref_thick_scene.json --quiet --lod 0 \
      --float -o "ref_thick_$name.exr"
  fi
  race "$name $size, vdb_render's medium" "$vox --scene thick_scene.json" "$vdb" "ref_thick_$name.exr"
  scene "\"absorption\":$thick, \"light_optical_depth\":0.1" >thick_scene.json
  race "$name $size, vdb_render's medium, light_optical_depth 0.1" "$vox --scene thick_scene.json" \
    "$vdb" "ref_thick_$name.exr"
  thin=$(echo "$vs" | awk '{ printf "%.6g,%.6g,%.6g", 0.5 * $1, 0.5 * $1, 0.5 * $1 }')
  race "$name $size, vox's medium" "$vox --scene scene.json" \
    "$vdb -absorb $thin -scatter $thin -gain 0"
  # The curve: vox's other quality settings.
  for q in '"light_step":64, "light_optical_depth":0.4, "shadow_lod":24' \
    '"light_step":32, "light_optical_depth":0.2, "shadow_lod":16' \
    '' \
    '"light_step":16, "light_optical_depth":0.1, "shadow_lod":8' \
    '"light_step":8, "light_optical_depth":0.05, "shadow_lod":4' \
    '"light_step":16, "light_optical_depth":0.1, "shadow_lod":0'; do
    scene "$q" >curve_scene.json
    rm -f curve.exr
    t=$(cpu_wall $render "$name.vox" --cam "cam_$name.json" --scene curve_scene.json --threads 1 \
      --quiet --float -o curve.exr | cut -d' ' -f1)
    echo "$name | ${q:-default} | $t | $(rmse_pct "ref_$name.exr" curve.exr "black_$name.exr")" >>curve.txt
  done
}

: >curve.txt
echo "| frame | vox CPU s | vox wall s | vdb_render CPU s | vdb_render wall s | CPU ratio | vox RMSE % of mean |"
echo "|---|---|---|---|---|---|---|"
frame sphere "-sphere" 256x256
frame dodec "-platonic f=12 s=1.0 v=0.006 w=3" 320x240
echo
echo "time against RMSE (one run each): frame | volume fields | vox CPU s | RMSE % of mean"
cat curve.txt

# The sphere lit from other directions (the light along x, from above, and
# vdb_render's default light, towards 0.3,0.3,0): vox's default, without
# the lattice, at light_optical_depth 0.05 and the exact frame, each against
# its converged image of that light.
echo
echo "other lights (sphere, one run each): light direction | volume fields | vox CPU s | RMSE % of mean"
for light_dir in '1,0,0' '0,-1,0' '-0.3,-0.3,0'; do
  ref="ref_light_$(echo "$light_dir" | tr ',-' '_m').exr"
  if [ ! -f "$ref" ]; then
    scene '"light_step":0.5, "light_optical_depth":0.01, "shadow_lod":0' >ref_scene.json
    $render sphere.vox --cam cam_sphere.json --scene ref_scene.json --threads 1 --quiet --lod 0 \
      --float -o "$ref"
  fi
  for q in '' '"light_lattice":false' '"light_optical_depth":0.05' 'exact'; do
    lod=
    if [ "$q" = exact ]; then scene '' >curve_scene.json && lod='--lod 0'; else scene "$q" >curve_scene.json; fi
    rm -f curve.exr
    t=$(cpu_wall $render sphere.vox --cam cam_sphere.json --scene curve_scene.json --threads 1 \
      --quiet --float $lod -o curve.exr | cut -d' ' -f1)
    echo "$light_dir | ${q:-default}${lod:+ (--lod 0)} | $t | $(rmse_pct "$ref" curve.exr black_sphere.exr)"
  done
done

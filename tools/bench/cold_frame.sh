#!/usr/bin/env bash
# cold_frame.sh VOX_RENDER STORE LIMIT_MB TAG [vox-render flags...]
#
# One cold frame of STORE, as a batch job with a memory limit runs it: drops
# the page cache (unless WARM=1), runs vox-render in a fresh cgroup v1 memory
# group limited to LIMIT_MB (0: unlimited, only measured), and prints wall
# time, the group's peak charge and failed charges, and the bytes the process
# read from disk. Camera: (0,0,3) looking at the origin, fov 40, 1024^2 (the
# full view of a unit-radius sphere); one directional light without shadows;
# 2 threads. Writes TAG.exr, TAG.json (--stats) and TAG.err in the current
# directory. DISK_MBPS=150 and DISK_IOPS=9300 (either or both) emulate a
# slower disk: the process then also runs in a cgroup v1 blkio group that
# throttles reads of the store's disk to that many MB/s and reads/s
# (tools/bench/disk_throttle.sh). Needs root and /sys/fs/cgroup/memory. Used for the out-of-core
# tables in docs/scale.md; the machine is shared, so compare runs made
# side by side, alternating.
set -euo pipefail
bin=$1; store=$2; lim=$3; tag=$4; shift 4
cg_root=/sys/fs/cgroup/memory
[ -d "$cg_root" ] || { echo "cold_frame.sh: no cgroup v1 memory controller at $cg_root" >&2; exit 2; }
cat > "$tag.cam.json" <<'EOF'
{"position":[0,0,3],"look_at":[0,0,0],"up":[0,1,0],"fov_deg":40,"width":1024,"height":1024,"projection":"perspective"}
EOF
cat > "$tag.scene.json" <<'EOF'
{"lights":[{"type":"directional","direction":[-1,-1,-1],"intensity":1.0,"shadows":false}]}
EOF
[ -n "${WARM:-}" ] || { sync; echo 3 > /proc/sys/vm/drop_caches; }
cg=$cg_root/vox-cold-$$
mkdir -p "$cg"
trap 'rmdir "$cg" 2>/dev/null || true' EXIT
if [ "$lim" -gt 0 ]; then echo $((lim << 20)) > "$cg/memory.limit_in_bytes"; fi
groups=("$cg")
if [ -n "${DISK_MBPS:-}${DISK_IOPS:-}" ]; then
  bg=$(dirname "$0")/disk_throttle.sh
  blk=$("$bg" create "$store" "vox-cold-$$")
  trap 'rmdir "$cg" 2>/dev/null || true; rmdir "$blk" 2>/dev/null || true' EXIT
  groups+=("$blk")
fi
start=$(date +%s.%N)
rc=0
sh -c 'n=$1; shift; for g in "$@"; do [ "$n" -gt 0 ] || break; echo $$ > "$g/cgroup.procs"; shift; n=$((n - 1)); done; exec "$@"' \
  sh "${#groups[@]}" "${groups[@]}" nice -n "${NICE:--15}" "$bin" "$store" \
  --cam "$tag.cam.json" --scene "$tag.scene.json" --threads 2 -o "$tag.exr" --stats "$tag.json" --quiet "$@" \
  2> "$tag.err" || rc=$?
end=$(date +%s.%N)
peak=$(cat "$cg/memory.max_usage_in_bytes"); fc=$(cat "$cg/memory.failcnt")
io=$(python3 -c "import json; d = json.load(open('$tag.json')); print(d['io']['read_bytes'], d['cache']['bricks_paged_in'], d['cache']['misses'])" 2>/dev/null || echo "- - -")
read -r rb paged misses <<< "$io"
printf "%s limit=%sMiB rc=%s wall=%.2fs peak=%.0fMiB failcnt=%s read_bytes=%s bricks_paged=%s ray_misses=%s\n" \
  "$tag" "$lim" "$rc" "$(echo "$end - $start" | bc)" "$(echo "$peak/1048576" | bc)" "$fc" "$rb" "$paged" "$misses"

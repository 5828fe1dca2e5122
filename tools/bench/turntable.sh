#!/usr/bin/env bash
# turntable.sh STORE [vox-render flags...]
#
# A turntable of STORE in one vox-render process (the frame-sequence benchmark):
# N frames (TURNTABLE, default 36) around the volume from --view 0,20, the
# first one cold (the page cache dropped first, unless WARM=1), in a fresh
# cgroup v1 memory group of LIMIT_MB (default 512; 0: unlimited). Prints
# each frame's render time (--stats timings.frame_seconds), its whole time
# (total_seconds: with the store's open for frame 1, set-up and writing) and
# the bricks it read from disk (cache.misses), then the mean of frames 2..N
# over frame 1's and whether it is at most GOAL (default 0.6): later frames
# find the bricks the earlier ones read in the cache of the one process.
#
# Environment: VOX_RENDER (default build/tools/render/vox-render), WORK
# (default: vox-turntable under /tmp; frames, stats and the log go there),
# TURNTABLE, LIMIT_MB, SIZE (default 1024x1024), THREADS (default 2), WARM,
# GOAL. Extra arguments go to vox-render (e.g. --lod 0, --memory-mb 400).
# Needs root and /sys/fs/cgroup/memory for the cold frame and the limit;
# without them it says so and runs warm and unlimited.
set -euo pipefail
if [[ $# -lt 1 ]]; then
  sed -n '2,19p' "$0" >&2
  exit 2
fi
store=$(realpath "$1")
shift
bin=$(realpath "${VOX_RENDER:-build/tools/render/vox-render}")
work=${WORK:-/tmp/vox-turntable}
n=${TURNTABLE:-36} lim=${LIMIT_MB:-512} size=${SIZE:-1024x1024} threads=${THREADS:-2}
goal=${GOAL:-0.6}
mkdir -p "$work"
rm -f "$work"/tt.*.exr "$work"/tt.*.json
cg_root=/sys/fs/cgroup/memory
run=("$bin" "$store" --view 0,20 --turntable "$n" --size "$size" --threads "$threads"
     -o "$work/tt.%04d.exr" --stats "$work/tt.%04d.json" "$@")
start=$(date +%s.%N)
rc=0
if [[ $(id -u) -eq 0 && -d $cg_root ]]; then
  [[ -n ${WARM:-} ]] || { sync; echo 3 > /proc/sys/vm/drop_caches; }
  cg=$cg_root/vox-turntable-$$
  mkdir -p "$cg"
  trap 'rmdir "$cg" 2>/dev/null || true' EXIT
  if [[ $lim -gt 0 ]]; then echo $((lim << 20)) > "$cg/memory.limit_in_bytes"; fi
  sh -c 'echo $$ > "$1/cgroup.procs"; shift; exec "$@"' sh "$cg" "${run[@]}" 2> "$work/tt.log" || rc=$?
  peak=$(( $(cat "$cg/memory.max_usage_in_bytes") >> 20 ))
  echo "cgroup: limit ${lim} MiB, peak ${peak} MiB, failcnt $(cat "$cg/memory.failcnt")"
else
  echo "turntable.sh: not root or no $cg_root: warm page cache, no memory limit" >&2
  "${run[@]}" 2> "$work/tt.log" || rc=$?
fi
end=$(date +%s.%N)
if [[ $rc -ne 0 ]]; then
  echo "turntable.sh: vox-render exited $rc; see $work/tt.log" >&2
  tail -5 "$work/tt.log" >&2
  exit 1
fi
printf "vox-render %s turntable of %d frames, %s, %s threads: %.1f s wall\n" \
  "$(basename "$store")" "$n" "$size" "$threads" "$(echo "$end - $start" | bc)"
python3 - "$work" "$n" "$goal" <<'EOF'
import json, sys
work, n, goal = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rows = []
print("frame  render_s  total_s  bricks_read  read_MiB")
for f in range(1, n + 1):
    d = json.load(open(f"{work}/tt.{f:04d}.json"))
    t = d["timings"]
    rows.append((t["frame_seconds"], t["total_seconds"]))
    print(f"{f:5d}  {t['frame_seconds']:8.3f}  {t['total_seconds']:7.3f}  "
          f"{d['cache']['misses']:11d}  {d['io']['read_bytes'] / 2**20:8.1f}")
if n < 2:
    sys.exit(0)
first, later = rows[0], rows[1:]
mean = [sum(r[i] for r in later) / len(later) for i in (0, 1)]
ratio = mean[0] / first[0]
print(f"frame 1: {first[0]:.3f} s render ({first[1]:.3f} s total); "
      f"frames 2-{n}: mean {mean[0]:.3f} s render ({mean[1]:.3f} s total)")
print(f"ratio (render): {ratio:.3f}  ratio (total): {mean[1] / first[1]:.3f}  "
      f"goal <= {goal}: {'met' if ratio <= goal else 'NOT met'}")
EOF

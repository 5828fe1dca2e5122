#!/usr/bin/env bash
# cold_overlap.sh VOX_RENDER STORE [RUNS] [MODES] [PREFETCH]
#
# Does a cold frame wait only for the disk? Measures, side
# by side and alternating, for each mode (exact = --lod 0, default = the
# store's level of detail) and each reading strategy (wait = the render
# threads read what they need, prefetch = --prefetch):
#   cold: page cache dropped, unlimited memory (tools/bench/cold_frame.sh);
#   warm: a new process right after, page cache warm, brick cache cold;
# and once, the disk's sequential bandwidth (dd of the store's bricks file,
# page cache dropped). Prints one row per run and, per mode and strategy, the
# medians and the goal's ratio cold / max(warm, bytes read / bandwidth)
# (goal: at most 1.1), each run's cold frame against the warm one measured
# right after it, then the median over runs. Camera and scene are cold_frame.sh's (full view of a
# unit sphere, 1024^2, 2 threads). RUNS defaults to 3, MODES to
# "exact default", PREFETCH to "wait prefetch". DISK_MBPS and DISK_IOPS
# emulate a slower disk for everything it reads (cold_frame.sh). Needs root
# (drops the page cache); writes its files in the current directory.
set -euo pipefail
bin=$1; store=$2; runs=${3:-3}; modes=${4:-exact default}; strategies=${5:-wait prefetch}
here=$(cd "$(dirname "$0")" && pwd)
bricks=$store/bricks.vxb
[ -f "$bricks" ] || { echo "cold_overlap.sh: no $bricks" >&2; exit 2; }

sync; echo 3 > /proc/sys/vm/drop_caches
size=$(stat -c %s "$bricks")
count=$(( size < (1 << 30) ? size >> 20 : 1024 ))
dd_in=(sh -c 'exec "$@"' sh)
if [ -n "${DISK_MBPS:-}${DISK_IOPS:-}" ]; then  # the same throttle as the frames'
  blk=$("$here/disk_throttle.sh" create "$store" "vox-overlap-$$")
  trap 'rmdir "$blk" 2>/dev/null || true' EXIT
  dd_in=(sh -c 'echo $$ > "$1/cgroup.procs"; shift; exec "$@"' sh "$blk")
fi
bw=$("${dd_in[@]}" dd if="$bricks" of=/dev/null bs=1M count="$count" 2>&1 | awk '/copied/ {print $(NF-1), $NF}')
mbps=$(python3 -c "v, u = '$bw'.split(); f = {'kB/s': 1e-3, 'MB/s': 1, 'GB/s': 1e3}[u]; print(float(v) * f)")
echo "disk: ${count} MiB of $bricks read sequentially at $mbps MB/s"

rows=()
for ((r = 1; r <= runs; r++)); do
  for mode in $modes; do
    for how in $strategies; do
      args=()
      [ "$mode" = exact ] && args+=(--lod 0)
      [ "$how" = prefetch ] && args+=(--prefetch)
      tag="co-$mode-$how"
      cold=$(NICE=0 "$here/cold_frame.sh" "$bin" "$store" 0 "$tag-cold" "${args[@]}")
      warm=$(WARM=1 NICE=0 "$here/cold_frame.sh" "$bin" "$store" 0 "$tag-warm" "${args[@]}")
      echo "run $r $mode $how: $cold"
      echo "run $r $mode $how: $warm"
      cw=$(sed -E 's/.* wall=([0-9.]+)s.*/\1/' <<< "$cold")
      ww=$(sed -E 's/.* wall=([0-9.]+)s.*/\1/' <<< "$warm")
      rb=$(sed -E 's/.* read_bytes=([0-9]+).*/\1/' <<< "$cold")
      python3 "$here/scale.py" --compare "$tag-cold.exr" "$tag-warm.exr" > /dev/null ||
        { echo "cold_overlap.sh: $tag: the cold and warm images differ" >&2; exit 1; }
      rows+=("$mode $how $cw $ww $rb")
    done
  done
done

python3 - "$mbps" "${rows[@]}" <<'EOF'
import statistics, sys
mbps = float(sys.argv[1])
groups = {}
for row in sys.argv[2:]:
    mode, how, cold, warm, rb = row.split()
    groups.setdefault((mode, how), []).append((float(cold), float(warm), int(rb)))
# The goal's ratio per run (its cold frame against the warm one right after
# it: drift on a shared machine cancels), then the median of those.
print(f"\n| mode | reads | cold s | warm s | MB read | disk s | cold / max(warm, disk) |")
print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
for (mode, how), v in groups.items():
    cold = statistics.median(c for c, _, _ in v)
    warm = statistics.median(w for _, w, _ in v)
    mb = statistics.median(b for _, _, b in v) / 1e6
    disk = mb / mbps
    ratio = statistics.median(c / max(w, b / 1e6 / mbps) for c, w, b in v)
    print(f"| {mode} | {how} | {cold:.2f} | {warm:.2f} | {mb:.0f} | {disk:.2f} | {ratio:.2f} |")
print(f"\nmedians of {len(next(iter(groups.values())))} runs; disk at {mbps:.0f} MB/s sequential")
EOF

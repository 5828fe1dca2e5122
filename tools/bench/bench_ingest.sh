#!/usr/bin/env bash
# Ingest benchmark: throughput, store size against the .vdb, bytes per
# occupied voxel and peak memory of vox-ingest on one .vdb file.
#   tools/bench/bench_ingest.sh [VOX_INGEST] [VDB] [THREADS]
# Defaults: build/tools/ingest/vox-ingest, sphere2048.vdb under /tmp (made with
# `vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3 -write VDB`
# when missing), 2 threads. CPU time and max RSS from /usr/bin/time; peak
# memory also sampled from /proc every 50 ms:
# RssAnon (the process's own memory) apart from RssFile (the memory-mapped
# .vdb, reclaimable page cache).
set -euo pipefail
bin=${1:-build/tools/ingest/vox-ingest}
vdb=${2:-/tmp/sphere2048.vdb}
threads=${3:-2}
if [ ! -f "$vdb" ]; then
  [ "$vdb" = /tmp/sphere2048.vdb ] || { echo "no $vdb" >&2; exit 1; }
  vdb_tool -sphere d=2048 r=1 c=0,0,0 v=0.001 w=3 -write "$vdb"
fi
out=$(mktemp -d)/store
log=$(mktemp)
start=$(date +%s.%N)
times=$(mktemp)
/usr/bin/time -o "$times" -f "%U %S %M" "$bin" "$vdb" "$out" --threads "$threads" 2>"$log" &
tpid=$!
peak_anon=0; peak_file=0
while kill -0 $tpid 2>/dev/null; do
  pid=$(pgrep -P $tpid | head -1 || true)
  if [ -n "$pid" ] && read -r a f < <(awk '/RssAnon/{a=$2} /RssFile/{f=$2} END{print a+0, f+0}' /proc/$pid/status 2>/dev/null); then
    [ "$a" -gt "$peak_anon" ] && peak_anon=$a
    [ "$f" -gt "$peak_file" ] && peak_file=$f
  fi
  sleep 0.05
done
wait $tpid
end=$(date +%s.%N)
grep -v '% .*bricks,' "$log"
read -r user sys maxrss < "$times"
cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN{print u + s}')
active=$(grep -o '[0-9]* active voxels read' "$log" | grep -o '^[0-9]*')
occupied=$(grep -o '[0-9]* occupied voxels' "$log" | grep -o '^[0-9]*')
vdb_bytes=$(stat -L -c %s "$vdb")  # -L: the file a symlink names
store_bytes=$(du -sb "$out" | cut -f1)
awk -v s="$start" -v e="$end" -v a="$active" -v o="$occupied" -v vb="$vdb_bytes" -v sb="$store_bytes" \
    -v pa="$peak_anon" -v pf="$peak_file" -v cpu="$cpu" -v mr="$maxrss" -v th="$threads" 'BEGIN {
  w = e - s; c = cpu;
  printf "wall %.2f s, cpu %.2f s (%d threads, load %s)\n", w, c, th, "'"$(cut -d' ' -f1-3 /proc/loadavg)"'";
  printf "throughput %.2f M active voxels/s wall; %.2f M/s per cpu-second (x%d cores if idle: %.2f M/s)\n", a / w / 1e6, a / c / 1e6, th, th * a / c / 1e6;
  printf "store %d bytes = %.1f%% of the .vdb (%d bytes); %.2f bytes per occupied voxel (%d occupied)\n", sb, 100 * sb / vb, vb, sb / o, o;
  printf "peak RssAnon %.1f MiB, peak RssFile (mapped .vdb) %.1f MiB (sampled every 50 ms); max RSS %.1f MiB (time -v, anon + file)\n", pa / 1024, pf / 1024, mr / 1024;
}'
rm -rf "$(dirname "$out")" "$log" "$times"

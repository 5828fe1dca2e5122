#!/usr/bin/env bash
# disk_throttle.sh create PATH NAME   (prints the group's directory)
#
# Emulates a slower disk for benchmarks: makes the cgroup v1 blkio group NAME
# whose reads from the disk holding PATH are throttled to DISK_MBPS MB/s
# (10^6 bytes) and DISK_IOPS reads/s (either may be unset: no limit on it).
# A process written to the group's cgroup.procs reads at that pace, its
# page-cache misses included (read-ahead too); the page cache itself is not
# throttled, so drop it first for a cold run. The caller removes the group
# (rmdir) when its processes are gone. Needs root and /sys/fs/cgroup/blkio.
set -euo pipefail
[ "${1:-}" = create ] && [ $# -eq 3 ] || { echo "usage: disk_throttle.sh create PATH NAME" >&2; exit 2; }
path=$2; name=$3
root=/sys/fs/cgroup/blkio
[ -w "$root" ] || { echo "disk_throttle.sh: no writable cgroup v1 blkio controller at $root" >&2; exit 2; }
src=$(df --output=source "$path" | tail -1)
disk=$(lsblk -ndo PKNAME "$src" 2>/dev/null || true)
[ -n "$disk" ] || disk=$(basename "$src")
dev=$(cat "/sys/block/$disk/dev")
g=$root/$name
mkdir -p "$g"
[ -z "${DISK_MBPS:-}" ] || echo "$dev $((DISK_MBPS * 1000000))" > "$g/blkio.throttle.read_bps_device"
[ -z "${DISK_IOPS:-}" ] || echo "$dev $DISK_IOPS" > "$g/blkio.throttle.read_iops_device"
echo "$g"

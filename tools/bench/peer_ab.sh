#!/usr/bin/env bash
# peer_ab.sh BEFORE AFTER SCRATCH_DIR SCENE [PAIRS]: two builds of
# vox-peer-bench (e.g. a copy of main's and a branch's) side by side on one of
# peer.sh's scenes (made in SCRATCH_DIR by peer.sh first), alternating BEFORE,
# AFTER, BEFORE, ... PAIRS times (default 3). Each run times vox against
# NanoVDB in one process (ROUNDS rounds, default 7), so each line's ratio is
# measured side by side; prints per run: binary, vox rays/s, NanoVDB rays/s,
# vox/NanoVDB, then the median ratio of each binary.
#   env ROUNDS (7), THREADS (2), VIEW (full or close: peer.sh's camera; default full)
set -euo pipefail
[ $# -ge 4 ] || { echo "usage: peer_ab.sh BEFORE AFTER SCRATCH_DIR SCENE [PAIRS]" >&2; exit 2; }
before=$(realpath "$1") after=$(realpath "$2") d=$(realpath "$3") s=$4 pairs=${5:-3}
for f in "$d/$s.vdb" "$d/$s.store" "$d/$s.${VIEW:-full}.cam.json"; do
  [ -e "$f" ] || { echo "peer_ab.sh: $f missing: run peer.sh BUILD $d $s first" >&2; exit 1; }
done
out=$(mktemp) err=$(mktemp)
trap 'rm -f "$out" "$err"' EXIT
for ((i = 0; i < pairs; ++i)); do
  for b in "$before" "$after"; do
    if ! "$b" "$d/$s.vdb" --store "$d/$s.store" --cam "$d/$s.${VIEW:-full}.cam.json" --rounds "${ROUNDS:-7}" \
      --threads "${THREADS:-2}" 2>"$err" >"$out"; then
      cat "$err" >&2
      exit 1
    fi
    python3 - "$b" "$out" <<'PY'
import json, sys
j = json.load(open(sys.argv[2]))
print(sys.argv[1], "%.3f M %.3f M %.3f" % (j["vox_rays_per_second"] / 1e6,
      j["nano_shaded_rays_per_second"] / 1e6, j["vox_over_nano_frame"]))
PY
  done
done | tee /dev/stderr | python3 -c '
import statistics, sys
r = {}
for line in sys.stdin:
    f = line.split()
    r.setdefault(f[0], []).append(float(f[-1]))
for b, v in r.items():
    print("median vox/NanoVDB %.3f (%s) %s" % (statistics.median(v), ", ".join("%.2f" % x for x in v), b))
'

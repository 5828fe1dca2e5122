#!/usr/bin/env bash
# Bit-identity check of two builds: the same inputs through each build's
# tools, then stores and images compared. For refactorings that must change
# no output.
#
# Usage: scripts/identical.sh OLD_BUILD NEW_BUILD [WORKDIR]
#   OLD_BUILD, NEW_BUILD  build directories (tools/*/vox-*, python/vox/)
#   WORKDIR               scratch directory (default: vox-identical under /tmp)
#
# Inputs (made once, shared by both builds): vox-gen sphere and bumpy at 256
# with their pyramid; the demo scene's .vdb (scripts/demo.sh's vdb_tool line)
# ingested; a fog volume (vdb_tool -ls2fog of it) ingested when vdb_tool is
# there. Each store is rendered with default flags, --lod 1, --layers
# normal,voxel, --float, and in three --tiles parts merged with vox-merge.
#
# Compared:
#   - vox-gen stores byte for byte (its writer is deterministic);
#   - ingested stores by logical content, since ingest writes its records in
#     the order its threads finish and a random store id: vox-info's report
#     (every count, size and histogram), the renders of each build, and the
#     new store rendered by the old build against the old store;
#   - every EXR pixel by pixel in every channel (as bits), and every header
#     attribute but the two timing slots (renderTimeSeconds, vox:timings)
#     and, for ingested stores, vox:storeId;
#     a --tiles part (which vox.read_exr refuses: tiles are missing) by its
#     attributes and each of its tiles' bytes (uncompressed; the order of
#     the tiles in the file follows the threads and varies from run to run);
#   - the PNG previews byte for byte.
# Exits 1 on any difference, with a one-line summary last.
# IDENTICAL_COMPARE_ONLY=1 compares the outputs an earlier run left in WORKDIR.
# When a build's defaults change on purpose: IDENTICAL_OLD_FLAGS and
# IDENTICAL_NEW_FLAGS are added to every render of that side but the --lod 1
# one, IDENTICAL_OLD_LOD_FLAGS and IDENTICAL_NEW_LOD_FLAGS to that one, and
# IDENTICAL_SKIP_ATTRS names header attributes left out of the comparison.
# Builds from before level of detail was the default: their default is the new
# --lod 0, and the old --lod 1 the new --lod 1 --silhouette-aa 0:
#   IDENTICAL_NEW_FLAGS="--lod 0" IDENTICAL_NEW_LOD_FLAGS="--silhouette-aa 0" \
#   IDENTICAL_SKIP_ATTRS=vox:lod scripts/identical.sh OLD NEW
set -uo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
old=$(cd "$1" && pwd) || exit 2
new=$(cd "$2" && pwd) || exit 2
work=${3:-/tmp/vox-identical}
repo=$(cd "$(dirname "$0")/.." && pwd)
python=/usr/bin/python3
[ -x "$python" ] || python=python3
threads=2
mkdir -p "$work"
work=$(cd "$work" && pwd)
log="$work/log.txt"
: >"$log"

fail() { echo "identical.sh: $*" >&2; exit 2; }
run() {  # run DIR CMD...: in DIR, output to the log
  local dir=$1; shift
  (cd "$dir" && "$@") >>"$log" 2>&1 || { echo "failed in $dir: $*" >&2; tail -5 "$log" >&2; return 1; }
}

# Shared inputs.
inputs="$work/inputs"
mkdir -p "$inputs"
if [ ! -s "$inputs/demo.vdb" ]; then
  command -v vdb_tool >/dev/null || fail "vdb_tool is needed for the demo .vdb"
  (cd "$inputs" && vdb_tool -platonic f=12 s=0.45 c=-0.45,0.0,0.0 v=0.002 w=3 \
     -sphere r=0.3 c=0.45,-0.1,0.1 v=0.002 w=3 -union -write demo.vdb) >>"$log" 2>&1 ||
    fail "vdb_tool could not make the demo .vdb"
fi
fog=0
if command -v vdb_tool >/dev/null; then
  if [ -s "$inputs/fog.vdb" ] ||
     (cd "$inputs" && vdb_tool -read demo.vdb -ls2fog -write fog.vdb) >>"$log" 2>&1; then
    fog=1
  fi
fi
# The demo camera at a smaller size; the gen stores use the default camera.
"$python" - "$repo/scripts/demo/cam.json" "$inputs/cam.json" <<'EOF'
import json, sys
cam = json.load(open(sys.argv[1]))
cam["width"], cam["height"] = 256, 192
json.dump(cam, open(sys.argv[2], "w"), indent=2)
EOF

# Stores and renders, once per build, in WORKDIR/old and WORKDIR/new with the
# same relative paths (a store's path is in vox-info's report and in the
# EXR headers).
make_outputs() {  # make_outputs BUILD SIDE
  local b=$1/tools d="$work/$2" flags lod_flags
  if [ "$2" = old ]; then
    read -r -a flags <<<"${IDENTICAL_OLD_FLAGS:-}"
    read -r -a lod_flags <<<"${IDENTICAL_OLD_LOD_FLAGS:-}"
  else
    read -r -a flags <<<"${IDENTICAL_NEW_FLAGS:-}"
    read -r -a lod_flags <<<"${IDENTICAL_NEW_LOD_FLAGS:-}"
  fi
  rm -rf "$d" && mkdir -p "$d" || return 1
  run "$d" "$b/gen/vox-gen" sphere sphere.store --size 256 --threads $threads --quiet || return 1
  run "$d" "$b/gen/vox-gen" bumpy bumpy.store --size 256 --threads $threads --quiet || return 1
  run "$d" "$b/ingest/vox-ingest" "$inputs/demo.vdb" demo.store --threads $threads --quiet || return 1
  if [ $fog = 1 ]; then
    run "$d" "$b/ingest/vox-ingest" "$inputs/fog.vdb" fog.store --threads $threads --quiet || return 1
  fi
  for s in $(stores); do
    (cd "$d" && "$b/info/vox-info" $s.store) >"$d/$s.info" 2>&1 || return 1
    local view=(--size 160x120)
    [ $s = demo ] && view=(--cam "$inputs/cam.json" --scene "$repo/scripts/demo/scene.json")
    local r=(run "$d" "$b/render/vox-render" $s.store "${view[@]}" --threads $threads
             --memory-mb 1G --quiet)
    "${r[@]}" -o $s-lod1.exr --lod 1 "${lod_flags[@]}" || return 1
    r+=("${flags[@]}")
    "${r[@]}" -o $s.exr --preview $s.png || return 1
    "${r[@]}" -o $s-layers.exr --layers normal,voxel || return 1
    "${r[@]}" -o $s-float.exr --float || return 1
    for i in 1 2 3; do "${r[@]}" -o $s-part$i.exr --tiles $i/3 || return 1; done
    run "$d" "$b/merge/vox-merge" $s-part1.exr $s-part2.exr $s-part3.exr -o $s-merged.exr || return 1
  done
}
stores() { echo sphere bumpy demo; [ $fog = 1 ] && echo fog; }

echo "identical.sh: old $old, new $new, work $work (log: $log)"
if [ "${IDENTICAL_COMPARE_ONLY:-0}" != 1 ]; then  # 1: compare what an earlier run made
make_outputs "$old" old || fail "the old build failed (see $log)"
make_outputs "$new" new || fail "the new build failed (see $log)"
# The new build's ingested stores read by the old build's renderer.
mkdir -p "$work/cross"
for s in $(stores); do
  case $s in sphere|bumpy) continue ;; esac
  run "$work/new" "$old/tools/render/vox-render" $s.store --size 160x120 --threads $threads \
      --memory-mb 1G --quiet ${IDENTICAL_OLD_FLAGS:-} -o ../cross/$s.exr || fail "the old build cannot render new/$s.store"
  run "$work/old" "$old/tools/render/vox-render" $s.store --size 160x120 --threads $threads \
      --memory-mb 1G --quiet -o ../cross/$s-ref.exr || fail "render of old/$s.store"
done
fi

diffs=0 checked=0
note() { echo "  DIFFERENT: $*"; diffs=$((diffs + 1)); }
for s in $(stores); do
  case $s in
    sphere|bumpy)  # deterministic writer: every file byte for byte
      while IFS= read -r f; do
        checked=$((checked + 1))
        cmp -s "$work/old/$f" "$work/new/$f" || note "$f"
      done < <(cd "$work/old" && find $s.store -type f | sort)
      [ "$(cd "$work/old" && find $s.store -type f | sort)" = \
        "$(cd "$work/new" && find $s.store -type f | sort)" ] || note "$s.store file list" ;;
    *)
      checked=$((checked + 1))
      cmp -s "$work/old/$s.info" "$work/new/$s.info" || note "$s.info (vox-info report)" ;;
  esac
  checked=$((checked + 1))
  cmp -s "$work/old/$s.png" "$work/new/$s.png" || note "$s.png"
done

# EXRs: headers (all attributes but the timing slots) and pixels (all
# channels, compared as bits), read with the old build's Python module.
pairs=()
for f in $(cd "$work/old" && ls *.exr); do pairs+=("$work/old/$f" "$work/new/$f"); done
for f in $(cd "$work/cross" && ls *.exr | grep -v -- -ref.exr); do
  pairs+=("$work/cross/${f%.exr}-ref.exr" "$work/cross/$f")
done
exr_out=$(INGESTED="demo fog" PYTHONPATH="$old/python" "$python" - "${pairs[@]}" <<'EOF'
import os, struct, sys
import numpy as np
import vox

SKIP = {"renderTimeSeconds", "vox:timings"} | set(
    a for a in os.environ.get("IDENTICAL_SKIP_ATTRS", "").split(",") if a)

def header(path):
    """(attribute name -> (type, raw value bytes), the bytes after the
    header) of a single-part EXR."""
    data = open(path, "rb").read(1 << 20)
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(path + ": not an EXR")
    at, attrs = 8, {}
    while data[at] != 0:
        name_end = data.index(b"\0", at)
        name = data[at:name_end].decode()
        type_end = data.index(b"\0", name_end + 1)
        kind = data[name_end + 1:type_end].decode()
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5:type_end + 5 + size]
        attrs[name] = (kind, value)
        at = type_end + 5 + size
    return attrs, open(path, "rb").read()[at + 1:], at + 1

def tiles(attrs, rest, base):
    """{(tx, ty, lx, ly): bytes} of a single-level tiled EXR's chunks (`rest`:
    the bytes after its header, which ends at file offset `base`). Tiles are written as they finish, so their
    order in the file, and the offset table, vary from run to run."""
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    tw, th = struct.unpack_from("<2I", attrs["tiles"][1])
    n = -(-(x1 - x0 + 1) // tw) * -(-(y1 - y0 + 1) // th)
    out = {}
    for (offset,) in struct.iter_unpack("<Q", rest[:8 * n]):
        if offset == 0:
            continue  # a tile this part does not hold
        at = offset - base
        key = struct.unpack_from("<4i", rest, at)
        (size,) = struct.unpack_from("<i", rest, at + 16)
        out[key] = rest[at + 20:at + 20 + size]
    return out

args = sys.argv[1:]
bad = 0
for a, b in zip(args[0::2], args[1::2]):
    why = []
    (ha, rest_a, base_a), (hb, rest_b, base_b) = header(a), header(b)
    # An ingested store's id is random: its images differ in vox:storeId only.
    ingested = os.path.basename(b).split("-")[0].split(".")[0] in os.environ["INGESTED"].split()
    for k in sorted(set(ha) | set(hb)):
        if k in SKIP or (ingested and k == "vox:storeId"):
            continue
        if ha.get(k) != hb.get(k):
            why.append("attribute " + k)
    try:
        ia, ib = vox.read_exr(a), vox.read_exr(b)
    except OSError:  # a --tiles part (missing tiles): its tiles byte for byte
        if tiles(ha, rest_a, base_a) != tiles(hb, rest_b, base_b):
            why.append("tile data")
        print(("DIFFERENT " if why else "same ") + b + (": " + ", ".join(why) if why else ""))
        bad += bool(why)
        continue
    ca, cb = ia["channels"], ib["channels"]
    if sorted(ca) != sorted(cb):
        why.append("channels %s vs %s" % (sorted(ca), sorted(cb)))
    for c in sorted(set(ca) & set(cb)):
        x, y = np.asarray(ca[c]), np.asarray(cb[c])
        if x.shape != y.shape or x.tobytes() != y.tobytes():
            n = "shape" if x.shape != y.shape else str(int(np.count_nonzero(
                x.view(np.uint32) != y.view(np.uint32)))) + " pixels"
            why.append("channel %s (%s)" % (c, n))
    print(("DIFFERENT " if why else "same ") + b + (": " + ", ".join(why) if why else ""))
    bad += bool(why)
print("exrs %d different %d" % (len(args) // 2, bad))
EOF
) || fail "the EXR comparison failed: $exr_out"
echo "$exr_out" | grep '^DIFFERENT' | sed 's/^DIFFERENT /  DIFFERENT: /'
exrs=$(echo "$exr_out" | tail -1 | awk '{print $2}')
exr_bad=$(echo "$exr_out" | tail -1 | awk '{print $4}')
diffs=$((diffs + exr_bad))
summary="$checked store files/reports/PNGs and $exrs EXRs compared (stores: $(stores | tr '\n' ' ')); fog: $([ $fog = 1 ] && echo yes || echo 'no vdb_tool')"
if [ $diffs -eq 0 ]; then
  echo "identical: $summary; no difference"
else
  echo "DIFFERENT: $summary; $diffs differences"
  exit 1
fi

#!/usr/bin/env bash
# Checks that includes point one way, floor by floor:
#   tools -> render, ingest -> storage -> core -> core/util
# Each floor may include its own headers and those of the floors below it,
# never a floor above (render and ingest, side by side, not each other), and
# OpenVDB headers only in ingest/ (tools/bench and tests that build volumes
# are outside the library floors). Reads every #include "..." of the library
# and tool sources git tracks, resolves it against the repository root and
# prints FILE:LINE: INCLUDE for each that points the wrong way; exits 1 if any.
# .ci/run runs it before the tests.
set -euo pipefail
cd "$(dirname "$0")/.."
git ls-files 'core/*' 'storage/*' 'ingest/*' 'render/*' 'tools/*' | grep -E '\.(h|hpp|cpp|cc)$' | python3 -c '
import re, sys
rank = {"core/util": 0, "core": 1, "storage": 2, "ingest": 3, "render": 3, "tools": 4}
def floor(path):
    if path.startswith("core/util/"): return "core/util"
    top = path.split("/")[0]
    return top if top in rank else None
bad = 0
for src in sys.stdin.read().split():
    f = floor(src)
    for no, line in enumerate(open(src, encoding="utf-8"), 1):
        m = re.match(r"\s*#\s*include\s*([\"<])([^\">]+)[\">]", line)
        if not m:
            continue
        inc = m.group(2)
        if inc.startswith("openvdb/") or inc.startswith("nanovdb/"):
            if f not in ("ingest", "tools"):
                print(f"{src}:{no}: {inc}: OpenVDB outside ingest/"); bad = 1
            continue
        g = floor(inc)
        if m.group(1) == "<" or g is None:
            continue
        if g == f:
            continue
        if rank[g] >= rank[f]:
            print(f"{src}:{no}: {inc}: {f} may not include {g}"); bad = 1
sys.exit(bad)
' || { echo "check-layers: the includes above point up or sideways" >&2; exit 1; }
echo "check-layers: includes point one way (tools -> render, ingest -> storage -> core -> core/util)"

#!/usr/bin/env bash
# Checks that every relative link and picture in the repository's Markdown
# files points at a file that exists, and that a link with a #fragment
# points at a heading of its page (GitHub's anchors: lower case, spaces to
# hyphens, punctuation dropped). Prints FILE:LINE: the broken link, and exits
# 1 if there is one. Code and scripts that name a page (docs/NAME.md, or
# storage/FORMAT.md) are held to the same: the page must exist.
# .ci/run runs it before the tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bad=0
git ls-files '*.md' | python3 -c '
import os, re, sys
def anchors(path):
    out, seen = set(), {}
    in_code = False
    for line in open(path, encoding="utf-8"):
        if line.startswith("```"):
            in_code = not in_code
        if in_code or not line.startswith("#"):
            continue
        text = line.lstrip("#").strip().lower()
        a = re.sub(r"[^\w\- ]", "", text).replace(" ", "-")
        n = seen.get(a, 0); seen[a] = n + 1
        out.add(a if n == 0 else f"{a}-{n}")
    return out
bad = 0
for md in sys.stdin.read().split():
    in_code = False
    for no, line in enumerate(open(md, encoding="utf-8"), 1):
        if line.startswith("```"):
            in_code = not in_code
        if in_code:
            continue
        line = re.sub(r"`[^`]*`", "", line)
        for target in re.findall(r"\]\(([^)\s]+)\)", line):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, frag = target.partition("#")
            full = os.path.normpath(os.path.join(os.path.dirname(md), path)) if path else md
            if not os.path.exists(full):
                print(f"{md}:{no}: {target}: no such file"); bad = 1
            elif frag and full.endswith(".md") and frag not in anchors(full):
                print(f"{md}:{no}: {target}: no such heading"); bad = 1
sys.exit(bad)
' || bad=1
refs=$(git ls-files | grep -vE '\.md$|^scripts/check-links\.sh$' | while IFS= read -r f; do
  [ -f "$f" ] || continue
  grep -noE '(docs/[A-Za-z0-9_./-]+|storage/FORMAT)\.md' "$f" 2>/dev/null | while IFS=: read -r no page; do
    [ -f "$page" ] || echo "$f:$no: $page: no such file"
  done
done) || true
if [ -n "$refs" ]; then printf '%s\n' "$refs"; bad=1; fi
[ "${bad:-0}" = 0 ] || { echo "check-links: the links above are broken" >&2; exit 1; }
echo "check-links: every relative link holds"

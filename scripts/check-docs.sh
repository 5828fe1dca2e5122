#!/usr/bin/env bash
# Checks the house rules for prose: docs, README, CHANGELOG and code comments
# say how things are now, so they name no numbered work item ("issue 12",
# "session 3", "item 4") and no path of the machine something ran on (the
# work, home and temporary directories, with a name after them); and every
# page under docs/ is at most 500 lines. Prints each offending line as
# FILE:LINE:TEXT and exits 1 if there is one, 0 otherwise.
# Markdown files are checked whole; C++ files on their comment lines (after
# // or on a /* or * line); shell and CMake files after a #; Python files
# after a # and, for numbered history, whole (their docstrings).
# Only files git tracks are read. .ci/run runs it before the tests.
set -uo pipefail
cd "$(dirname "$0")/.."
history='\b(issue|session)s? #?[0-9]+|\bitems? [0-9]+\b'
machine='/(work|home)/|/tmp/[A-Za-z0-9_]'
pat="($history|$machine)"
found=0
report() { [ -n "$1" ] && { printf '%s\n' "$1"; found=1; }; }
while IFS= read -r f; do
  [ -f "$f" ] || continue
  case "$f" in
    scripts/check-docs.sh) ;;
    *.md) report "$(grep -nHiE "$pat" "$f")" ;;
    *.h | *.hpp | *.cpp | *.cc | *.c | *.inl) report "$(grep -nHiE "(//|^[[:space:]]*/?\*).*$pat" "$f")" ;;
    *.py) report "$(grep -nHiE "$history|#.*($machine)" "$f")" ;;
    *.sh | *.cmake | *CMakeLists.txt | .ci/*) report "$(grep -nHiE "#.*$pat" "$f")" ;;
  esac
done < <(git ls-files)
while IFS= read -r f; do
  n=$(wc -l < "$f")
  if [ "$n" -gt 500 ]; then
    echo "$f: $n lines (a docs page is at most 500)"
    found=1
  fi
done < <(git ls-files 'docs/*.md')
if [ "$found" -ne 0 ]; then
  echo "check-docs: the lines above tell history by number, cite a machine path or overrun a page" >&2
  exit 1
fi
echo "check-docs: docs, README, CHANGELOG and code comments pass"

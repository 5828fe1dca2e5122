#!/bin/sh
# PROGRAM --version prints one line "NAME VERSION (git DESCRIBE)" on stdout,
# nothing on stderr, exits 0, and --version wins wherever it stands. In a
# git checkout DESCRIBE names a commit of SOURCE_DIR's repository (with
# -dirty when the tree had changes at build time); elsewhere it is "unknown".
#
#   version_test.sh PROGRAM NAME VERSION SOURCE_DIR
set -eu
prog=$1 name=$2 version=$3 src=$4
fail() { echo "version_test: $name: $*" >&2; exit 1; }
err=$(mktemp)
trap 'rm -f "$err"' EXIT

out=$("$prog" --version 2>"$err") || fail "--version exited $?"
[ ! -s "$err" ] || fail "--version wrote to stderr: $(cat "$err")"
[ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] || fail "--version printed more than one line: $out"
case "$out" in
  "$name $version (git "*")") ;;
  *) fail "--version printed '$out', not '$name $version (git ...)'" ;;
esac
describe=${out#"$name $version (git "}
describe=${describe%)}
echo "$out"

# After other arguments, even ones the tool would refuse, it is still --version.
out2=$("$prog" /nonexistent-store --no-such-flag --version 2>"$err") ||
  fail "--version after other arguments exited $?"
[ "$out2" = "$out" ] || fail "--version after other arguments printed '$out2'"

top=$(git -C "$src" rev-parse --show-toplevel 2>/dev/null || true)
if [ -n "$top" ] && [ "$(cd "$top" && pwd -P)" = "$(cd "$src" && pwd -P)" ]; then
  [ "$describe" != unknown ] || fail "built from a git checkout but describes itself as unknown"
  commit=${describe%-dirty}
  commit=${commit##*-g}  # v0.9.0-3-g1a7f09f -> 1a7f09f; a bare hash stays
  git -C "$src" rev-parse -q --verify "$commit^{commit}" >/dev/null ||
    git -C "$src" rev-parse -q --verify "${describe%-dirty}^{commit}" >/dev/null ||
    fail "'$describe' is not a commit of $src"
else
  [ "$describe" = unknown ] || fail "not a git checkout, yet describes itself as '$describe'"
fi

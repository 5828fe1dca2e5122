#!/bin/sh
# `cmake --install BUILD --prefix TMP`, then the installed copy on its own:
# every program in PREFIX/bin answers --version, none of them (nor the Python
# extension) has an RPATH/RUNPATH into the build tree, vox-gen + vox-info +
# vox-render work on a tiny store from the prefix, the documentation is in
# PREFIX/share/doc/vox, no benchmark is installed, and, when the module is
# built, the installed package imports from the prefix (PYTHONPATH) and says
# its version.
#
#   install_test.sh BUILD_DIR VERSION PYTHON|none PYTHON_INSTALL_DIR PROGRAM...
set -eu
build=$1 version=$2 python=$3 pydir=$4
[ "$python" != none ] || python=""
shift 4
tmp=$(mktemp -d "${TMPDIR:-/tmp}/vox-install-test.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
prefix=$tmp/prefix
fail() { echo "install_test: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" >"$tmp/install.log" 2>&1 ||
  { cat "$tmp/install.log" >&2; fail "cmake --install failed"; }

# The programs: present, runnable from the prefix, their --version line.
for p in "$@"; do
  [ -x "$prefix/bin/$p" ] || fail "$prefix/bin/$p not installed"
  line=$("$prefix/bin/$p" --version) || fail "$p --version failed"
  case "$line" in
    "$p $version (git "*")") ;;
    *) fail "$p --version printed '$line'" ;;
  esac
done
for f in "$prefix"/bin/*; do
  case " $* " in *" $(basename "$f") "*) ;; *) fail "unexpected program installed: $f" ;; esac
done

# Nothing installed looks into the build tree for libraries.
build_abs=$(cd "$build" && pwd -P)
if command -v readelf >/dev/null; then
  for f in "$prefix"/bin/* $(find "$prefix" -name '_vox*.so'); do
    if readelf -d "$f" | grep -E 'RPATH|RUNPATH' | grep -F "$build_abs" >/dev/null; then
      fail "$f has an RPATH into the build tree: $(readelf -d "$f" | grep -E 'RPATH|RUNPATH')"
    fi
  done
fi

# A tiny store, made, described and rendered by the installed programs.
cd "$tmp"
"$prefix/bin/vox-gen" sphere "$tmp/s.store" --size 32 --threads 2 --quiet ||
  fail "vox-gen from the prefix failed"
"$prefix/bin/vox-info" "$tmp/s.store" >"$tmp/info.txt" || fail "vox-info from the prefix failed"
"$prefix/bin/vox-render" "$tmp/s.store" --size 32x24 --threads 2 -o "$tmp/s.exr" --quiet ||
  fail "vox-render from the prefix failed"
[ -s "$tmp/s.exr" ] || fail "vox-render wrote no $tmp/s.exr"

# The documentation, laid out as in the source tree.
doc=$prefix/share/doc/vox
for f in README.md CHANGELOG.md storage/FORMAT.md docs/getting-started.md docs/performance.md \
         docs/accuracy-paper.svg docs/lod/sphere8k-off-vs-lod1.png; do
  [ -s "$doc/$f" ] || fail "$doc/$f not installed"
done

# The Python package from the prefix, not from the build tree.
if [ -n "$python" ]; then
  [ -f "$prefix/$pydir/vox/__init__.py" ] || fail "$prefix/$pydir/vox/__init__.py not installed"
  PYTHONPATH="$prefix/$pydir" "$python" -c "
import os, sys, vox
prefix = os.path.realpath(sys.argv[1])
assert os.path.realpath(vox.__file__).startswith(prefix + os.sep), vox.__file__
assert os.path.realpath(vox._vox.__file__).startswith(prefix + os.sep), vox._vox.__file__
assert vox.__version__ == sys.argv[2], vox.__version__
assert vox.Store(sys.argv[3]).info['voxels'] > 0
print('vox', vox.__version__, vox.__git_describe__, 'from', os.path.dirname(vox.__file__))
" "$prefix" "$version" "$tmp/s.store" || fail "the installed Python module did not import"
fi
echo "install_test: ok ($prefix)"

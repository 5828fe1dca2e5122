#!/usr/bin/env bash
# Fails when ctest skipped a test: reads the JUnit files ctest wrote
# (--output-junit) and lists every test reported as skipped (a GoogleTest
# program whose test called GTEST_SKIP, tests/common/gtest_main.cpp; the
# Python suite without its module; SKIP_RETURN_CODE 77). .ci/run runs it
# after each ctest: CI runs as root with a v1 memory cgroup and installs
# pybind11 and numpy, so every default test can run there, and a skip is a
# test that did not do its job.
#   scripts/check-skips.sh build/ctest-junit.xml [...]
# VOX_ALLOW_SKIPS=1 lists the skips without failing (a run without root or
# without a memory cgroup). VOX_EXPECTED_SKIPS=name,... names tests whose
# skip is by design there (python_module_test in a sanitizer build, which
# leaves the module out).
set -euo pipefail
python3 - "$@" <<'PY'
import os, sys
import xml.etree.ElementTree as ET
expected = set(filter(None, os.environ.get("VOX_EXPECTED_SKIPS", "").split(",")))
skipped = []
for path in sys.argv[1:]:
    for case in ET.parse(path).getroot().iter("testcase"):
        s = case.find("skipped")
        if s is not None and case.get("name") not in expected:
            out = (case.findtext("system-out") or "").strip().splitlines()
            why = next((l.strip() for l in out if "SKIPPED" in l or "skipped" in l), s.get("message", ""))
            skipped.append("%s (%s): %s" % (case.get("name"), os.path.basename(path), why))
if not skipped:
    sys.exit(0)
allow = os.environ.get("VOX_ALLOW_SKIPS") == "1"
print("check-skips: %d test%s skipped%s:" % (len(skipped), "" if len(skipped) == 1 else "s",
      " (allowed: VOX_ALLOW_SKIPS=1)" if allow else ""), file=sys.stderr)
for s in skipped:
    print("  " + s, file=sys.stderr)
if not allow:
    print("check-skips: every default test can run on CI (root, a memory cgroup, pybind11 "
          "and numpy); VOX_ALLOW_SKIPS=1 allows skips where they cannot", file=sys.stderr)
    sys.exit(1)
PY

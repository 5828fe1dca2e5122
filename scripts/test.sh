#!/usr/bin/env bash
# Builds vox and runs the default test suite (tests labelled "long" are left out;
# run them with: ctest --test-dir build -L long). ctest's results also go to
# build/ctest-junit.xml, where .ci/run looks for skipped tests (scripts/check-skips.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh
ctest --test-dir build --output-on-failure -LE long -j "$(nproc)" --output-junit ctest-junit.xml

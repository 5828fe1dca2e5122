#!/usr/bin/env bash
# Builds vox and runs the default test suite (tests labelled "long" are left out;
# run them with: ctest --test-dir build -L long).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh
ctest --test-dir build --output-on-failure -LE long -j "$(nproc)"

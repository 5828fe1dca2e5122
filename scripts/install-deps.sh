#!/usr/bin/env bash
# Installs vox's build and test dependencies from Debian's packages, when missing.
# clang and its runtime libraries (sanitizers, libFuzzer) are for the ASan+UBSan
# and fuzzing stage (scripts/sanitize.sh asan, scripts/fuzz.sh).
set -euo pipefail
pkgs=(build-essential cmake ninja-build pkg-config
      libopenvdb-dev libopenvdb-tools libnanovdb-dev libboost-dev libboost-iostreams-dev libimath-dev
      libopenexr-dev libzstd-dev libglm-dev libtbb-dev nlohmann-json3-dev libpng-dev
      libcli11-dev libgtest-dev libgmock-dev libbenchmark-dev libgmp-dev python3
      python3-dev pybind11-dev python3-numpy python3-pytest python3-matplotlib
      clang libclang-rt-14-dev libcpp-httplib-dev chromium python3-websocket)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq "${missing[@]}"
fi

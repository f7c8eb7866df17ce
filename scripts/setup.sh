#!/usr/bin/env bash
# Shared by sample.sh and test.sh: installs the Debian 12 packages that are missing, then configures
# and builds into build/. Usage: setup.sh [engine|all]  ("all" adds Blender and the test tools).
set -euo pipefail
cd "$(dirname "$0")/.."

engine_packages=(build-essential cmake pkg-config libeigen3-dev libsuitesparse-dev libopenvdb-dev
  libboost-iostreams-dev libopencv-dev libtbb-dev nlohmann-json3-dev libcli11-dev libgtest-dev
  libbenchmark-dev libnlopt-cxx-dev ffmpeg mpi-default-dev)
test_packages=(blender python3-pytest python3-numpy python3-matplotlib xvfb xauth libegl-mesa0
  libgl1-mesa-dri mpi-default-bin)

packages=("${engine_packages[@]}")
[ "${1:-engine}" = all ] && packages+=("${test_packages[@]}")

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ]; then
    echo "Installing: ${missing[*]}"
    apt-get update -q
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
  else
    echo "Missing packages. Run once:  sudo apt-get install ${missing[*]}" >&2
    exit 1
  fi
fi

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j"$(nproc)"

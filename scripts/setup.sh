#!/usr/bin/env bash
# Shared by sample.sh and test.sh: installs the Debian 12 packages that are missing, then configures
# and builds into build/. Usage: setup.sh [engine|sample|tests|all]  ("sample" adds Blender, which
# renders the sample's reference clip, and matplotlib, which draws identify's plots; "tests" builds
# the GoogleTest suite and the benchmarks besides the engine; "all" is both, with the tools the
# add-on's tests need).
set -euo pipefail
cd "$(dirname "$0")/.."

engine_packages=(build-essential cmake pkg-config libeigen3-dev libsuitesparse-dev libopenvdb-dev
  libboost-dev libboost-iostreams-dev libopencv-dev libtbb-dev nlohmann-json3-dev libcli11-dev
  ffmpeg mpi-default-dev)
sample_packages=(blender python3-matplotlib)
build_test_packages=(libgtest-dev libbenchmark-dev libnlopt-cxx-dev)
test_packages=(python3-pytest python3-numpy xvfb xauth libegl-mesa0 libgl1-mesa-dri mpi-default-bin)

packages=("${engine_packages[@]}")
# The engine alone, unless the tests are to run: they are most of the build.
build=(-DVISCOSCOPE_BUILD_TESTS=OFF -DVISCOSCOPE_BUILD_BENCH=OFF)
target=(--target viscoscope)
case "${1:-engine}" in
  engine) ;;
  sample) packages+=("${sample_packages[@]}") ;;
  tests|all)
    packages+=("${build_test_packages[@]}")
    [ "$1" = all ] && packages+=("${sample_packages[@]}" "${test_packages[@]}")
    build=(-DVISCOSCOPE_BUILD_TESTS=ON -DVISCOSCOPE_BUILD_BENCH=ON)
    target=() ;;
  *) echo "setup.sh: unknown argument '$1' (engine, sample, tests or all)" >&2; exit 2 ;;
esac

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

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "${build[@]}"
cmake --build build -j"$(nproc)" "${target[@]}"

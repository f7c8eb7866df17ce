#!/usr/bin/env bash
# All tests: native GoogleTest suites and the Blender add-on tests, through CTest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh all
cd build
ctest --output-on-failure -j1 "$@"

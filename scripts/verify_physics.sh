#!/usr/bin/env bash
# The full-size physics verification (DESIGN.md "Physics checks"): the same checks CI runs on coarse
# grids, at the sizes the figures in the issue notes quote. Prints the figures; takes ~30 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh tests
VISCOSCOPE_FULL_VERIFICATION=1 build/tests/native/sim_physics_test --gtest_also_run_disabled_tests
# The thin-film forward model against theory, and against the 3D solver on twice the CI's grid.
build/tests/native/film_test
VISCOSCOPE_FULL_VERIFICATION=1 build/tests/native/identify_film_test --gtest_filter='FilmAgainstSimulation.*'

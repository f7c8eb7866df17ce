#!/usr/bin/env bash
# The main job: builds the engine and simulates the embedded capture scene (honey draining from a
# cup with a hole onto the ground) into out/capture_cup/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh engine
build/bin/viscoscope simulate sample_scenes/capture_cup.json --out out/capture_cup "$@"
echo "Frames written to out/capture_cup/ (frame_*.vdb, particles_*.bin, simulation.json)"

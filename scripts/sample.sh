#!/usr/bin/env bash
# The main job: what "Identify viscosity" does, on the embedded capture scene (honey, η = 8 Pa·s,
# draining from a cup with a hole onto the ground), from the command line.
#   1. `synth`: simulate the scene at 64³ with another particle seed than identification uses and
#      render it through Blender (Cycles) into a phone-like clip, out/capture_cup/synth/reference.mp4;
#   2. `identify`: extract that clip's silhouettes like footage (against the rendered clean plate, no
#      mask of the cup: the opaque cup hides what it hides in the simulated silhouettes too) and search
#      η by CMA-ES over 60³ simulations (the grid the cup's hole needs, as the add-on raises it to)
#      with no time budget, the add-on's default: the search ends when it settles, on the same
#      path on any machine, into out/capture_cup/identify/;
#   3. print η* with its interval against the truth.
# About 21 minutes on 2 cores after the build (3 for the clip, 18 for the search and its grid checks). Ctrl-C stops it
# with its work kept; running it again resumes both steps where they stopped. Extra arguments go to
# `identify` (e.g. --threads 1).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh sample

out=out/capture_cup
mkdir -p "$out"
build/bin/viscoscope synth sample_scenes/capture_cup.json --camera sample_scenes/capture_camera.json \
  --out "$out/synth"

# The add-on's defaults (Identify panel): start at 5 Pa·s, spread ×3, two grid placements in turn, the
# grid raised to 60, at most 20 generations, no time budget.
# Paths are relative to the job file.
cat > "$out/job.json" <<'JOB'
{
  "format": "viscoscope.job", "version": 1,
  "scene": "../../sample_scenes/capture_cup.json",
  "camera": "synth/camera.json",
  "video": "synth/reference.mp4",
  "extraction": {"clean_plate": "synth/clean_plate.png", "weights": "0:0"},
  "parameters": [{"name": "viscosity", "initial": 5, "spread": 10, "min": 0.001, "max": 10000}],
  "resolution": 60,
  "grid_placements": 2,
  "max_generations": 20,
  "time_budget_s": 0,
  "seed": 3
}
JOB
build/bin/viscoscope identify "$out/job.json" --out "$out/identify" "$@"

/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
truth = json.load(open(out + "/synth/synth.json"))["truth"]["viscosity"]
eta = json.load(open(out + "/identify/result.json"))["viscosity"]
low, high = eta["interval"]
print("η* = %.4g Pa·s, interval [%.4g, %.4g]; the clip's truth %.4g Pa·s: %+.1f %%"
      % (eta["value"], low, high, truth, 100 * (eta["value"] / truth - 1)))
print("Results, plots and θ*'s fields: %s/identify/ (result.json, convergence.png, landscape.png, fields/)" % out)
PY

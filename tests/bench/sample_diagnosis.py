#!/usr/bin/python3
"""One diagnosis of the sample cup within a wall-clock budget (issue 64: base and every candidate
within 30 minutes on a 2-core machine).

1. `synth` simulates the sample cup (`sample_scenes/capture_cup.json`, honey η = 8 Pa·s) at 64³ with
   particle seed 11 and has Blender render it into a clip, as `scripts/sample.sh` does; with
   `--hidden '{"type": "herschel_bulkley", ...}'` the clip's liquid follows that law instead (the
   scene's "material.model"), an effect the job does not declare.
2. `viscoscope diagnose` on the job `scripts/sample.sh` writes (the clip's silhouettes extracted like
   footage, η searched from 5 Pa·s, seed 3) at `--resolution`, with `--time-budget` for the whole
   diagnosis: the Newtonian base and each candidate the cup can hold.
3. Prints the diagnosis's wall time against the budget, and each fit's parameters, evaluations,
   search and scoring seconds, held-out E and BIC, the noise floor and the conclusion.

    /usr/bin/python3 tests/bench/sample_diagnosis.py [--budget 1800] [--resolution 48] [--hidden JSON]
        [--effects a,b] [--work DIR] [--reuse-clip] [--threads N]
"""
import argparse
import json
import pathlib
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]


def run(command, what):
    started = time.monotonic()
    done = subprocess.run([str(c) for c in command], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{what} failed (exit {done.returncode}): {done.stderr.strip()[-2000:]}")
    return time.monotonic() - started


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--budget", type=float, default=1800, help="wall seconds for the whole diagnosis")
    parser.add_argument("--resolution", type=int, default=48, help="the diagnosis's grid")
    parser.add_argument("--hidden", help="the clip's material model as a scene's material.model (JSON)")
    parser.add_argument("--threads", type=int, default=0, help="engine threads (0 = all cores)")
    parser.add_argument("--reuse-clip", action="store_true",
                        help="diagnose WORK/synth's clip as it is (camera.json, reference.mp4, clean_plate.png) "
                             "instead of running synth, which re-simulates after any engine change")
    parser.add_argument("--effects", help="the candidates, comma-separated (default: every one the cup can hold)")
    parser.add_argument("--work", default=str(ROOT / "out/sample_diagnosis"), help="folder for the clip and results")
    args = parser.parse_args()
    work = pathlib.Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)

    scene_file = ROOT / "sample_scenes/capture_cup.json"
    clip_scene = scene_file
    if args.hidden:
        scene = json.loads(scene_file.read_text())
        scene["material"]["model"] = json.loads(args.hidden)
        clip_scene = work / "clip_scene.json"
        clip_scene.write_text(json.dumps(scene, indent=1))
    synth_seconds = 0.0
    if not args.reuse_clip:
        synth_seconds = run([args.engine, "synth", clip_scene, "--camera", ROOT / "sample_scenes/capture_camera.json",
                             "--out", work / "synth"], "synth")

    job = {"format": "viscoscope.job", "version": 1, "scene": str(scene_file), "camera": "synth/camera.json",
           "video": "synth/reference.mp4",
           "extraction": {"clean_plate": "synth/clean_plate.png", "weights": "0:0"},
           "parameters": [{"name": "viscosity", "initial": 5, "spread": 10, "min": 0.001, "max": 10000}],
           "resolution": args.resolution, "grid_placements": 2, "seed": 3}
    (work / "job.json").write_text(json.dumps(job, indent=1))
    out = work / "diagnosis"
    # A fresh diagnosis: diagnose resumes each fit from a checkpoint it finds there.
    shutil.rmtree(out, ignore_errors=True)
    seconds = run([args.engine, "diagnose", work / "job.json", "--out", out, "--time-budget", args.budget,
                   "--threads", args.threads, "--progress", "none", "--no-plots"]
                  + (["--effects", args.effects] if args.effects else []), "diagnose")
    report = json.loads((out / "diagnosis.json").read_text())

    print(f"clip: {clip_scene.name}{' with ' + args.hidden if args.hidden else ''} ({synth_seconds:.0f} s to make or "
          f"reuse); diagnosis at {args.resolution}³: {seconds:.0f} s wall against a {args.budget:.0f} s budget "
          f"({seconds / args.budget:.2f}×); fits and scoring {report['seconds']:.0f} s")
    for fit in [report["base"]] + report["candidates"]:
        parameters = ", ".join(f"{name} {p['value']:.4g} [{p['interval'][0]:.3g}, {p['interval'][1]:.3g}]"
                               for name, p in fit["parameters"].items())
        print(f"  {fit['model']:15s} {parameters}; {fit['evaluations']} evaluations, search {fit['seconds']:.0f} s "
              f"(budget {fit['time_budget_s']:.0f}), scoring {fit['scoring_seconds']:.0f} s; fitted E "
              f"{fit['fitted_E']:.4g}, held-out E {fit['held_out_E']:.4g}, BIC {fit['bic']:.1f}"
              + (f", held-out gain {fit['held_out_gain']:+.2f}" if "held_out_gain" in fit else ""))
    if "base_refit" in report:
        refit = report["base_refit"]
        other = refit["unused_fit"]
        values = ", ".join("%s %.4g" % (name, p["value"]) for name, p in other["parameters"].items())
        outcome = "replaced the first fit" if refit["replaced_first_fit"] else "the first fit stands"
        print(f"  base refit from {refit['from']}'s fit: {outcome} (the other: {values}, "
              f"held-out E {other['held_out_E']:.4g})")
    for skipped in report["not_tried"]:
        print(f"  not tried: {skipped['effect']} ({skipped['why']})")
    noise = report["noise_floor"]
    print(f"noise floor: held-out E of the base's θ* over {len(noise['held_out_E'])} seeds and placements "
          f"{', '.join('%.4g' % e for e in noise['held_out_E'])}; ln E spread {noise['log_spread']:.3f}, "
          f"gains under {100 * noise['visible_share']:.0f} % within it ({noise['seconds']:.0f} s)")
    print(f"{report['verdict']}: {report['conclusion']}; E before {report['errors']['E']['before']:.4g}, "
          f"after {report['errors']['E']['after']:.4g}")
    for line in report["what_would_tell"]:
        print(f"  what would tell: {line}")


if __name__ == "__main__":
    main()

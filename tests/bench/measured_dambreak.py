#!/usr/bin/python3
"""Identification against measured data: the viscosity of the corn syrup in the lock-release dam
break of ../shared/data/measured/dambreak_syrup_validation.csv, identified from its filmed front
alone, against the viscometer's readings on the same fluid (9.88–10.32 Pa·s at 0.07–0.36 s⁻¹; the
power-law fit K = 9.712 Pa·sⁿ, n = 0.979; see that folder's README).

1. The scene: the lock (0.2 m long, filled 0.0443 m deep) at the closed end of a channel 0.55 m
   long, ρ = 1540 kg/m³, Newtonian, without surface tension. The source does not give the channel's
   width, so by default the channel is infinitely wide (periodic across, 2 cells) and the drag of its
   side walls is missing from the model; --channel-width W puts walls W apart.
2. A job whose reference is the measured front alone: `track` with the observable "front" along
   the channel from the gate (the CSV measures from there), no camera, no silhouettes.
3. `viscoscope identify`: η*, its interval and the front's relative error sqrt(Σ(sim − measured)² /
   Σ measured²) there.
4. `identify_landscape_bench` at the viscometer's readings and around η*: E and the front's error,
   on the job's grid and moved half a cell.

With `--diagnose` the same front goes to `viscoscope diagnose` instead: η searched as the base, a
channel as wide as the domain (`--max-width`) whose width the side-walls candidate may search, and
every candidate effect; it prints the conclusion, each model's parameters and E over the fitted and
the held-out frames, and the front's error before and after.

With `--unknown channel_width` the viscosity is instead fixed at the viscometer's (the mean of its
readings, half their spread as the uncertainty: the job's "fixed"), and the width of the channel,
side walls of a "channel" solid inside a domain `--max-width` wide, is what the front identifies;
with `--unknown both` the front alone identifies the two at once.

    /usr/bin/python3 tests/bench/measured_dambreak.py [--resolution 100] [--channel-width 0.1] [--work DIR]
    /usr/bin/python3 tests/bench/measured_dambreak.py --unknown channel_width [--max-width 0.3]
    /usr/bin/python3 tests/bench/measured_dambreak.py --diagnose [--resolution 60] [--generations 6] [--effects a,b]
    /usr/bin/python3 tests/bench/measured_dambreak.py --diagnose --experiment particles

`--fix-viscosity` holds η at the viscometer's (10.10 ± 0.22 Pa·s, the job's `fixed`, nothing
searched) and lets each effect fit its own parameters alone.

`--experiment particles` takes the second dam break of that folder instead (syrup with 15 % plastic
particles, a lock filled 0.084 m deep, ρ = 1391 kg/m³, no viscometer): diagnose only.
"""
import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
VISCOMETER = (9.876, 10.32)  # Pa·s, the lowest and highest apparent viscosity read
# The two dam breaks of that folder: the lock's fill depth (m), the liquid's density (kg/m³), the
# channel's length modelled past the 0.2 m lock (m, beyond the farthest front) and the domain's height.
EXPERIMENTS = {
    "validation": {"data": "dambreak_syrup_validation.csv", "depth": 0.0443, "density": 1540, "length": 0.55,
                   "height": 0.055},
    # Syrup with 15 % plastic particles; no viscometer. Its front reaches 0.474 m from the gate.
    "particles": {"data": "dambreak_syrup_example.csv", "depth": 0.084, "density": 1391, "length": 0.75,
                  "height": 0.1},
}


def front_job(args, data, lock, origin_y, parameters):
    """A job whose reference is the measured front alone, along the channel from the gate."""
    return {"format": "viscoscope.job", "version": 1, "scene": "scene.json",
            "track": {"csv": str(data), "column": "front_m", "observable": "front",
                      "origin": [lock, origin_y, 0], "direction": [1, 0, 0], "band": 0.0065},
            "parameters": parameters, "max_generations": args.generations, "seed": 3}


def run_engine(args, command, work, out, *options):
    """Runs `viscoscope COMMAND WORK/job.json --out WORK/OUT`; its wall seconds, or exits with its error."""
    started = time.monotonic()
    run = subprocess.run([args.engine, command, work / "job.json", "--out", work / out, "--progress", "none",
                          *options], capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"{command} failed (exit {run.returncode}): {run.stderr.strip()}")
    return time.monotonic() - started


VISCOSITY_SEARCHED = {"name": "viscosity", "initial": 5, "spread": 10, "min": 0.01, "max": 1000}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", choices=sorted(EXPERIMENTS), default="validation",
                        help="which dam break: the syrup with its viscometer, or the one with particles (--diagnose only)")
    parser.add_argument("--data", help="the front's CSV (default: the experiment's in ../shared/data/measured)")
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--landscape", default=str(ROOT / "build/bench/identify_landscape_bench"))
    parser.add_argument("--resolution", type=int, default=100, help="cells along the channel")
    parser.add_argument("--generations", type=int, default=30)
    parser.add_argument("--channel-width", type=float, help="m between side walls (default: none, periodic)")
    parser.add_argument("--work", help="folder for the scene, job and results (default: a temporary one)")
    parser.add_argument("--unknown", choices=("viscosity", "channel_width", "both"), default="viscosity")
    parser.add_argument("--max-width", type=float, default=0.3, help="m: the widest channel searched")
    parser.add_argument("--diagnose", action="store_true", help="run viscoscope diagnose on the front")
    parser.add_argument("--effects", help="with --diagnose: the candidates, comma-separated (default: every one)")
    parser.add_argument("--fix-viscosity", action="store_true",
                        help="with --diagnose: η held at the viscometer's, each effect fitting its own parameters alone")
    args = parser.parse_args()
    args.lock = EXPERIMENTS[args.experiment]
    args.data = args.data or str(ROOT.parent / "shared/data/measured" / args.lock["data"])
    if args.fix_viscosity and (args.experiment != "validation" or not args.diagnose):
        sys.exit("--fix-viscosity needs --diagnose on the validation dam break, the one with a viscometer")
    if args.experiment != "validation" and not args.diagnose:
        sys.exit("only the validation dam break has a viscometer to compare with: use --diagnose")
    if args.diagnose:
        return diagnose(args)
    if args.unknown != "viscosity":
        return identify_channel_width(args)
    data = pathlib.Path(args.data).resolve()
    if not data.is_file():
        sys.exit(f"measured data not found: {data}")
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="viscoscope_dambreak_"))
    work.mkdir(parents=True, exist_ok=True)
    lock, depth, length = 0.2, args.lock["depth"], args.lock["length"]
    width = args.channel_width or 2 * length / args.resolution
    scene = {"format": "viscoscope.scene", "version": 1,
             "domain": {"min": [0, 0, 0], "max": [length, width, args.lock["height"]], "resolution": args.resolution,
                        "periodic": [False, args.channel_width is None, False]},
             "liquids": [{"type": "box", "min": [0, 0, 0], "max": [lock, width, depth]}],
             "material": {"density": args.lock["density"], "viscosity": 10, "surface_tension": 0.0},
             "gravity": [0, 0, -9.81], "fps": 4, "frames": 1, "seed": 3}
    (work / "scene.json").write_text(json.dumps(scene, indent=1))
    job = front_job(args, data, lock, width / 2, [VISCOSITY_SEARCHED])
    (work / "job.json").write_text(json.dumps(job, indent=1))
    wall = run_engine(args, "identify", work, "identify")
    result = json.loads((work / "identify/result.json").read_text())
    eta = result["viscosity"]["value"]
    low, high = result["viscosity"]["interval"]
    best = [e for e in result["evaluated"] if e["fidelity"] == "full" and e["theta"][0] == eta][0]
    walls = f"side walls {args.channel_width} m apart" if args.channel_width else "no side walls (periodic)"
    print(f"dam break, {args.resolution} cells along the channel, {walls}, the front compared over "
          f"{result['frames']} frames at 4 fps")
    print(f"identified η* = {eta:.4g} Pa·s, interval [{low:.4g}, {high:.4g}], "
          f"front error {100 * best['track_error']:.2f} %, {result['evaluations']} evaluations, {wall:.0f} s")
    print(f"viscometer {VISCOMETER[0]}–{VISCOMETER[1]} Pa·s: η* is {eta / VISCOMETER[1]:.3f}–{eta / VISCOMETER[0]:.3f}× it")

    thetas = [VISCOMETER[0], VISCOMETER[1], 0.9 * eta, eta, 1.1 * eta]
    landscape = subprocess.run([args.landscape, "--job", work / "job.json", "--work", work / "identify",
                                "--thetas", ",".join(f"{t:.6g}" for t in thetas), "--shifts", "0,0.5"],
                               capture_output=True, text=True)
    if landscape.returncode != 0:
        sys.exit(f"identify_landscape_bench failed: {landscape.stderr.strip()}")
    print(landscape.stdout, end="")


def channel_scene(args, work, width):
    """DIR/scene.json: the lock in a channel `width` wide inside a domain --max-width wide plus two
    cells, so that the widest walls searched stay inside it; the lock's length and depth."""
    lock, depth, length = 0.2, args.lock["depth"], args.lock["length"]
    dx = length / args.resolution
    half = args.max_width / 2 + 2 * dx
    scene = {"format": "viscoscope.scene", "version": 1,
             "domain": {"min": [0, -half, 0], "max": [length, half, args.lock["height"]], "resolution": args.resolution},
             "solids": [{"type": "channel", "center_y": 0, "width": width}],
             "liquids": [{"type": "box", "min": [0, -half, 0], "max": [lock, half, depth]}],
             "material": {"density": args.lock["density"], "viscosity": 10, "surface_tension": 0.0},
             "gravity": [0, 0, -9.81], "fps": 4, "frames": 1, "seed": 3}
    (work / "scene.json").write_text(json.dumps(scene, indent=1))
    return lock


def diagnose(args):
    """The effect the Newtonian model of the dam break lacks, from the filmed front alone."""
    data = pathlib.Path(args.data).resolve()
    if not data.is_file():
        sys.exit(f"measured data not found: {data}")
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="viscoscope_dambreak_diagnose_"))
    work.mkdir(parents=True, exist_ok=True)
    lock = channel_scene(args, work, args.max_width)
    job = front_job(args, data, lock, 0, [] if args.fix_viscosity else [VISCOSITY_SEARCHED])
    if args.fix_viscosity:
        job["fixed"] = [{"name": "viscosity", "value": sum(VISCOMETER) / 2, "uncertainty": (VISCOMETER[1] - VISCOMETER[0]) / 2}]
    (work / "job.json").write_text(json.dumps(job, indent=1))
    wall = run_engine(args, "diagnose", work, "diagnose", *(["--effects", args.effects] if args.effects else []))
    d = json.loads((work / "diagnose/diagnosis.json").read_text())
    print(f"dam break, {args.resolution} cells along the channel, {args.generations} generations per fit, "
          f"fitted frames {d['fitted_frames']}, {wall:.0f} s: {d['conclusion']}")
    for model in [d["base"]] + d["candidates"]:
        values = ", ".join(f"{name} = {p['value']:.4g} [{p['interval'][0]:.4g}, {p['interval'][1]:.4g}]"
                           for name, p in model["parameters"].items())
        print(f"  {model['model']}: {values}; E fitted {model['fitted_E']:.4g}, held out {model['held_out_E']:.4g}, "
              f"BIC {model['bic']:.1f}, front error {100 * model.get('track_error', float('nan')):.2f} %, "
              f"{model['evaluations']} evaluations, {model['seconds']:.0f} s")
    for tried in d["not_tried"]:
        print(f"  not tried: {tried['effect']}: {tried['why']}")
    errors = d["errors"]
    print(f"front error before {100 * errors['track_error']['before']:.2f} %, after "
          f"{100 * errors['track_error']['after']:.2f} %; held-out E {errors['held_out_E']['before']:.4g} -> "
          f"{errors['held_out_E']['after']:.4g}")


def identify_channel_width(args):
    """The channel's width from the filmed front, with η held at the viscometer's or searched too."""
    data = pathlib.Path(args.data).resolve()
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="viscoscope_dambreak_width_"))
    work.mkdir(parents=True, exist_ok=True)
    lock = channel_scene(args, work, 0.1)
    eta, uncertainty = sum(VISCOMETER) / 2, (VISCOMETER[1] - VISCOMETER[0]) / 2
    job = front_job(args, data, lock, 0, [{"name": "solids[0].width", "initial": 0.1, "spread": 0.05, "min": 0.04,
                                            "max": args.max_width}])
    if args.unknown == "both":
        job["parameters"].append({"name": "viscosity", "initial": 5, "spread": 10, "min": 0.5, "max": 100})
    else:
        job["fixed"] = [{"name": "viscosity", "value": eta, "uncertainty": uncertainty}]
    (work / "job.json").write_text(json.dumps(job, indent=1))
    wall = run_engine(args, "identify", work, "identify", "--no-fields")
    result = json.loads((work / "identify/result.json").read_text())
    width = result["parameters"]["solids[0].width"]
    held = (f"η fixed at {eta:.4g} ± {uncertainty:.2g} Pa·s" if args.unknown == "channel_width" else "η searched too")
    print(f"dam break, {args.resolution} cells along the channel, {held}")
    best = [e for e in result["evaluated"]
            if e["fidelity"] == "full" and e["theta"] == [result["parameters"][p["name"]]["value"]
                                                          for p in job["parameters"]]][0]
    print(f"identified channel width W* = {100 * width['value']:.2f} cm, interval "
          f"[{100 * width['interval'][0]:.2f}, {100 * width['interval'][1]:.2f}] cm, front error "
          f"{100 * best['track_error']:.2f} %, {result['evaluations']} evaluations, {wall:.0f} s")
    if args.unknown == "both":
        viscosity = result["parameters"]["viscosity"]
        print(f"identified η* = {viscosity['value']:.4g} Pa·s, interval [{viscosity['interval'][0]:.4g}, "
              f"{viscosity['interval'][1]:.4g}] (viscometer {VISCOMETER[0]}–{VISCOMETER[1]} Pa·s)")


if __name__ == "__main__":
    main()

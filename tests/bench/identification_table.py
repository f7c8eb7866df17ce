#!/usr/bin/python3
"""Table 1 of Takahashi & Lin 2019 for Viscoscope: viscosity recovered from synthetic references.

For each true η, with the built engine only:
  1. `viscoscope synth` the capture scene (sample_scenes/capture_cup.json) at η, at the reference
     resolution and seed, seen by a side camera that sees the cup and the puddle: a Blender-rendered
     mp4, its clean plate and the cup's exclusion mask;
  2. a job whose reference is that clip (extracted like footage: MOG2 against the clean plate, the cup
     excluded, frame 0 weighted 0) and whose identification runs at another resolution and seed;
  3. `viscoscope identify`, which also re-simulates θ* at the identification resolution and writes
     its fields (OUT/fields/frame_*.vdb);
  4. `viscoscope compare` of those fields against the reference simulation's hidden ones;
  5. the same at the true η: `viscoscope simulate` at the identification's resolution and seed, and
     `compare` again. That is the floor the identification's grid leaves (ε_p⁰, ε_v⁰): the paper's
     hidden fields were scored at the resolution they were identified at, these against a finer grid;
  6. `compare` of θ*'s fields against the true η's on that same grid and seed (ε_p¹, ε_v¹): what the
     error in η alone does to the hidden fields, as the paper scored them;
and prints η_true, η*, ε_η = |η* − η|/η, ε_p, ε_v, ε_p⁰, ε_v⁰, ε_p¹, ε_v¹, the evaluations, the
wall times (the search alone, and the whole `identify` with extraction and θ*'s fields), the profile
parabola's vertex (not used as θ*) and the interval.

The defaults are the issue's target (identification 48³, 60 frames) and take hours. The reference
is 96³, where the sample cup's drain has nearly converged: at η = 1 the share drained by frame 8
was within 2 % of 128³'s, where 64³ drained 8 % more, so a 64³ reference scores the 48³ model
against a different flow rather than against the physics. (Since particles are mirrored into walls,
the flux out of the hole over frames 4–24 at η = 100 is 2.4 % above 128³'s at 96³, 6.8 % at 48³.) Try it small first:

    /usr/bin/python3 tests/bench/identification_table.py --etas 1,10,100 \\
        --reference-resolution 32 --resolution 24 --frames 24
"""
import argparse
import json
import math
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]


def side_camera(width, height, focal_px):
    """A "viscoscope.camera" 0.45 m in front of the cup (−y), slightly above it, aimed between the
    cup and the ground so that both the cup and the puddle under it are in the picture."""
    centre = (0.0, -0.45, 0.12)
    target = (0.0, 0.0, 0.07)
    forward = normalized([t - c for t, c in zip(target, centre)])
    right = normalized(cross(forward, (0.0, 0.0, 1.0)))
    down = cross(forward, right)
    rotation = [right, down, forward]
    translation = [-sum(r * c for r, c in zip(row, centre)) for row in rotation]
    return {"format": "viscoscope.camera", "version": 1, "width": width, "height": height,
            "K": [[focal_px, 0, (width - 1) / 2], [0, focal_px, (height - 1) / 2], [0, 0, 1]],
            "distortion": [0, 0, 0, 0, 0], "R": rotation, "t": translation}


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def normalized(v):
    length = math.sqrt(sum(x * x for x in v))
    return tuple(x / length for x in v)


def run(command, log):
    """Runs an engine command; on failure prints its stderr and stops."""
    started = time.monotonic()
    # An --engine built or copied outside this checkout finds render_reference.py here.
    env = dict(os.environ)
    env.setdefault("VISCOSCOPE_SCRIPTS", str(ROOT / "scripts"))
    with open(log, "w", encoding="utf-8") as out:
        result = subprocess.run([str(c) for c in command], stdout=subprocess.PIPE, stderr=out, text=True, env=env)
    if result.returncode != 0:
        sys.exit(f"{' '.join(str(c) for c in command)} failed (exit {result.returncode}):\n"
                 + pathlib.Path(log).read_text(encoding="utf-8"))
    return result.stdout, time.monotonic() - started


def clip_step(args, eta):
    """Frames between compared frames. The drain rate through the hole scales about as 1/η, so above
    --slow-eta the clip is that many times longer and compared every that many frames: still
    --frames compared frames, and about as much liquid outside the cup at the end as at --slow-eta."""
    return max(1, round(eta / args.slow_eta))


def one_row(args, eta, work):
    work.mkdir(parents=True, exist_ok=True)
    step = clip_step(args, eta)
    camera = work / "side_camera.json"
    camera.write_text(json.dumps(side_camera(args.width, args.height, args.focal)))
    synth = work / "synth"
    synth_command = [args.engine, "synth", args.scene, "--camera", camera, "--out", synth,
                     "--resolution", args.reference_resolution, "--seed", args.reference_seed,
                     "--viscosity", eta, "--frames", args.frames * step, "--samples", args.samples, "--progress", "none"]
    # A --keep folder's finished reference is reused when made with the same arguments (whichever
    # engine binary ran them; its time is then shown as "reused").
    made_by = work / "synth_command.json"
    command_text = json.dumps([str(a) for a in synth_command[1:]])
    if (synth / "reference.mp4").exists() and made_by.exists() and made_by.read_text() == command_text:
        synth_s = None
    else:
        made_by.unlink(missing_ok=True)
        _, synth_s = run(synth_command, work / "synth.log")
        made_by.write_text(command_text)
    initial = math.sqrt(args.eta_min * args.eta_max)  # the same start for every η: the geometric middle
    job = {
        "format": "viscoscope.job", "version": 1,
        "scene": str(pathlib.Path(args.scene).resolve()),
        "camera": "synth/camera.json",
        "video": "synth/reference.mp4",
        "extraction": {"clean_plate": "synth/clean_plate.png", "exclude_mask": "synth/exclude.png",
                       "weights": "0:0", "step": step},  # frame 0 is the same for every η
        "parameters": [{"name": "viscosity", "initial": initial, "spread": 3 * initial,
                        "min": args.eta_min, "max": args.eta_max, "log": True}],
        "resolution": args.resolution,
        "max_generations": args.generations,
        "time_budget_s": args.time_budget,
        "seed": args.seed,
        "grid_placements": args.grid_placements,
        "grid_placement_schedule": args.placement_schedule,
        "area_track_weight": args.area_track_weight,
    }
    (work / "job.json").write_text(json.dumps(job, indent=1))
    identify = [args.engine, "identify", work / "job.json", "--out", work / "identify", "--progress", "none",
                "--no-plots"]
    if args.threads:
        identify += ["--threads", args.threads]
    # identify resumes from a folder's checkpoint, even a finished run made by another build, which
    # would print that run's numbers as this one's: every row searches afresh.
    shutil.rmtree(work / "identify", ignore_errors=True)
    _, identify_s = run(identify, work / "identify.log")
    result = json.loads((work / "identify" / "result.json").read_text())
    identified = work / "identify" / "fields"
    fields = hidden_field_errors(args, synth / "simulation", identified, work / "compare.log")
    floor = fields_at_true_eta(args, eta, step, work)
    same_grid = hidden_field_errors(args, work / "true_eta", identified, work / "compare_same_grid.log")
    eta_star = result["viscosity"]["value"]
    # The budget rule's prediction of a full-fidelity generation (made at the switch) against them.
    predicted = [g["predicted_fine_generation_s"] for g in result["history"] if "predicted_fine_generation_s" in g]
    full_seconds = [g["seconds"] for g in result["history"] if g["fidelity"] == "full"]
    return {"eta": eta, "eta_star": eta_star, "eps_eta": abs(eta_star - eta) / eta,
            "eps_p": fields["epsilon_p"], "eps_v": fields["epsilon_v"],
            "floor_p": floor["epsilon_p"], "floor_v": floor["epsilon_v"],
            "same_grid_p": same_grid["epsilon_p"], "same_grid_v": same_grid["epsilon_v"],
            "evaluations": result["evaluations"], "identify_s": identify_s, "synth_s": synth_s,
            "search_s": result["timings"]["wall_s"], "stop": result["stop"],
            "vertex": result["viscosity"].get("profile_fit", {}).get("theta_min", math.nan),
            "interval": result["viscosity"]["interval"], "warnings": result.get("warnings", []),
            "predicted_full_s": predicted[-1] if predicted else None, "full_s": full_seconds}


def hidden_field_errors(args, reference, sim, log):
    """`compare`'s JSON for the fields in `sim` against those in `reference`."""
    compared, _ = run([args.engine, "compare", "--reference", reference, "--sim", sim], log)
    return json.loads(compared)


def fields_at_true_eta(args, eta, step, work):
    """hidden_field_errors for the scene simulated at the true η on the identification's grid and seed."""
    scene = json.loads(pathlib.Path(args.scene).read_text())
    scene["material"]["viscosity"] = eta
    scene["domain"]["resolution"] = args.resolution
    scene["seed"] = args.seed
    scene["frames"] = args.frames * step
    scene["output"] = {"particles": False, "vdb": True, "mesh": False}
    path = work / "true_eta_scene.json"
    path.write_text(json.dumps(scene, indent=1))
    run([args.engine, "simulate", path, "--out", work / "true_eta", "--progress", "none"], work / "true_eta.log")
    return hidden_field_errors(args, work / "synth" / "simulation", work / "true_eta",
                               work / "compare_true_eta.log")


def percent(x):
    return "   n/a" if x is None else f"{100 * x:6.1f}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--etas", default="1,3,10,30,100,300", help="true viscosities, Pa·s, comma-separated")
    parser.add_argument("--reference-resolution", type=int, default=96, help="synth's resolution")
    parser.add_argument("--resolution", type=int, default=48, help="the identification's resolution")
    parser.add_argument("--frames", type=int, default=60,
                        help="compared frames after the initial one (at the scene's fps)")
    parser.add_argument("--slow-eta", type=float, default=100,
                        help="above this η the clip is η/slow-eta times longer, compared at that step")
    parser.add_argument("--reference-seed", type=int, default=11)
    parser.add_argument("--seed", type=int, default=3, help="the identification's seed (CMA-ES and particles)")
    parser.add_argument("--generations", type=int, default=40, help="max_generations of the job")
    parser.add_argument("--grid-placements", type=int, default=2,
                        help="grid_placements of the job: grids moved k/n cell sideways")
    parser.add_argument("--placement-schedule", choices=["each_evaluation", "by_generation"], default="by_generation",
                        help="grid_placement_schedule of the job: every evaluation on all placements, or one per "
                             "full-fidelity generation in turn")
    parser.add_argument("--area-track-weight", type=float, default=1,
                        help="area_track_weight of the job: the reference's silhouette area over time in E "
                             "(0 = the silhouettes alone)")
    parser.add_argument("--time-budget", type=float, default=600,
                        help="time_budget_s of the job: wall seconds for the search (0 = none)")
    parser.add_argument("--eta-min", type=float, default=0.1)
    parser.add_argument("--eta-max", type=float, default=3000)
    parser.add_argument("--samples", type=int, default=8, help="Cycles samples per pixel")
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--focal", type=float, default=260, help="focal length in pixels")
    parser.add_argument("--threads", type=int, default=0, help="identify's worker threads (0 = all cores)")
    parser.add_argument("--scene", default=str(ROOT / "sample_scenes/capture_cup.json"))
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--keep", metavar="DIR", help="work in DIR and keep it (default: a temporary folder)")
    args = parser.parse_args()
    etas = [float(x) for x in args.etas.split(",")]

    root = pathlib.Path(args.keep) if args.keep else pathlib.Path(tempfile.mkdtemp(prefix="viscoscope_table_"))
    print(f"reference {args.reference_resolution}³ seed {args.reference_seed}, identification {args.resolution}³ "
          f"seed {args.seed}, {args.frames} compared frames (clips longer above η = {args.slow_eta:g}), "
          f"{args.width}x{args.height} camera, {args.samples} spp; "
          f"work in {root}", flush=True)
    header = (f"{'η_true':>8} {'η*':>9} {'ε_η %':>6} {'ε_p %':>6} {'ε_v %':>6} {'ε_p⁰ %':>6} {'ε_v⁰ %':>6} "
              f"{'ε_p¹ %':>6} {'ε_v¹ %':>6} "
              f"{'evals':>6} {'search s':>8} {'identify s':>10} {'synth s':>8} {'vertex':>9}  interval  stop")
    print(header, flush=True)
    try:
        for eta in etas:
            row = one_row(args, eta, root / f"eta_{eta:g}")
            print(f"{row['eta']:8g} {row['eta_star']:9.4g} {percent(row['eps_eta'])} {percent(row['eps_p'])} "
                  f"{percent(row['eps_v'])} {percent(row['floor_p'])} {percent(row['floor_v'])} "
                  f"{percent(row['same_grid_p'])} {percent(row['same_grid_v'])} "
                  f"{row['evaluations']:6d} {row['search_s']:8.1f} {row['identify_s']:10.1f} "
                  f"{'reused' if row['synth_s'] is None else format(row['synth_s'], '.1f'):>8} {row['vertex']:9.4g}  "
                  f"[{row['interval'][0]:.3g}, {row['interval'][1]:.3g}]  {row['stop']}", flush=True)
            if row["predicted_full_s"] and row["full_s"]:
                print(f"{'':8} full generations: predicted {row['predicted_full_s']:.1f} s at the switch, measured "
                      + ", ".join(f"{s:.1f}" for s in row["full_s"]) + " s", flush=True)
            for warning in row["warnings"]:
                print(f"{'':8} warning: {warning}", flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()

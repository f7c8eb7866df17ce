#!/usr/bin/python3
"""Benchmark: Viscoscope's solver against Blender's Mantaflow on the capture-cup scene.

A benchmark, not a test: it prints figures and ratios measured in the same run and never asserts
on time.  Run from anywhere with Debian's Python (standard library only):

    /usr/bin/python3 tests/bench/solver_vs_mantaflow.py [--frames 10] [--json build/bench/solver_vs_mantaflow.json]

For each resolution (cells along the longest axis) and dynamic viscosity η it runs

* Viscoscope: `viscoscope simulate` on sample_scenes/capture_cup.json with that resolution, η and
  frame count, particle/VDB/mesh output off (so no file writing and no surface phase is timed);
* Mantaflow: tests/bench/mantaflow_bake.py inside `blender -b --factory-startup`, which builds the
  same cup, liquid and domain and times only `bpy.ops.fluid.bake_all()` with the variational
  viscosity on, viscosity_value = ν · 0.4 / L² (ν = η/ρ, L = longest domain side in m; DESIGN.md).

The two engines run interleaved, one configuration after the other, so that load from other jobs
on the machine hits both alike.  Each engine call's peak resident memory comes from os.wait4() on
that very child (RUSAGE_CHILDREN would be a running maximum over all children).
"""

import argparse
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAKE_SCRIPT = os.path.join(REPO, "tests", "bench", "mantaflow_bake.py")
TARGET_RATIO = 0.5  # Viscoscope wall / Mantaflow bake, per configuration


def csv_numbers(kind):
    return lambda text: [kind(x) for x in text.split(",") if x.strip()]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=10, help="frames to simulate (default 10)")
    p.add_argument("--resolutions", type=csv_numbers(int), default=[32, 48, 64],
                   help="comma-separated resolutions (default 32,48,64)")
    p.add_argument("--viscosities", type=csv_numbers(float), default=[1.0, 10.0, 100.0],
                   help="comma-separated dynamic viscosities in Pa·s (default 1,10,100)")
    p.add_argument("--repeat", type=int, default=1,
                   help="runs per configuration and engine; medians are reported (default 1)")
    p.add_argument("--json", default=os.path.join(REPO, "build", "bench", "solver_vs_mantaflow.json"),
                   help="where to write the table as JSON")
    p.add_argument("--scene", default=os.path.join(REPO, "sample_scenes", "capture_cup.json"))
    p.add_argument("--viscoscope", default=os.path.join(REPO, "build", "bin", "viscoscope"))
    p.add_argument("--blender", default="/usr/bin/blender")
    p.add_argument("--surface-tension", type=float,
                   help="σ in N/m for Viscoscope (default: the scene's). Mantaflow's bake keeps "
                        "Blender's default surface_tension = 0, so 0 here compares like with like")
    p.add_argument("--skip-mantaflow", action="store_true", help="run Viscoscope only")
    p.add_argument("--workdir", help="keep scenes, outputs and caches here (default: a temp dir, removed)")
    return p.parse_args()


def run_child(cmd, log_path, cwd=None):
    """Run cmd to completion; return (exit code, wall seconds, peak RSS in MiB of that child)."""
    with open(log_path, "wb") as log:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=cwd)
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)  # Popen must not wait() a reaped child
    return proc.returncode, wall, usage.ru_maxrss / 1024.0  # ru_maxrss is in KiB on Linux


def tail(path, lines=12):
    try:
        with open(path, "r", errors="replace") as f:
            return "".join(f.readlines()[-lines:])
    except OSError:
        return ""


def median_or_none(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def run_viscoscope(args, base_scene, res, eta, work, rep):
    tag = f"vs_r{res}_eta{eta:g}_{rep}"
    scene = json.loads(json.dumps(base_scene))
    scene["domain"]["resolution"] = res
    scene["material"]["viscosity"] = eta
    if args.surface_tension is not None:
        scene["material"]["surface_tension"] = args.surface_tension
    scene["frames"] = args.frames
    scene["output"] = {"particles": False, "vdb": False, "mesh": False}
    scene_path = os.path.join(work, tag + ".json")
    out_dir = os.path.join(work, tag)
    with open(scene_path, "w") as f:
        json.dump(scene, f, indent=1)
    code, wall, peak = run_child([args.viscoscope, "simulate", scene_path, "--out", out_dir,
                                  "--progress", "none"], os.path.join(work, tag + ".log"))
    record = {"exit_code": code, "wall_seconds": wall, "peak_mib": peak}
    sim_path = os.path.join(out_dir, "simulation.json")
    if code != 0 or not os.path.exists(sim_path):
        record["error"] = tail(os.path.join(work, tag + ".log"))
        return record
    with open(sim_path) as f:
        sim = json.load(f)
    frames = sim["frames"]
    phases = {k: sum(fr["seconds"][k] for fr in frames) for k in ("transfer", "solve", "other")}
    phase_total = sum(phases.values())
    steps = sum(fr["steps"] for fr in frames)
    iterations = sum(fr["solver_iterations"] for fr in frames)
    fps = float(sim["scene"].get("fps", base_scene.get("fps", 30)))
    record.update({
        "engine_wall_seconds": sim["wall_seconds"],
        "simulated_seconds": len(frames) / fps,
        "wall_per_simulated_second": wall / (len(frames) / fps),
        "steps": steps,
        "solver_iterations": iterations,
        "median_iterations_per_step": statistics.median(
            fr["solver_iterations"] / fr["steps"] for fr in frames if fr["steps"] > 0),
        "mean_iterations_per_step": iterations / steps if steps else None,
        "all_converged": all(fr.get("converged", True) for fr in frames),
        "phase_seconds": phases,
        "phase_shares": {k: (v / phase_total if phase_total > 0 else None) for k, v in phases.items()},
        "setup_and_untimed_seconds": sim["wall_seconds"] - phase_total,
        "volume_drift": sim["volume_drift"],
        "max_speed_last_frame": frames[-1]["max_speed"] if frames else None,
    })
    return record


def mantaflow_viscosity_value(base_scene, eta):
    rho = float(base_scene["material"]["density"])
    lo, hi = base_scene["domain"]["min"], base_scene["domain"]["max"]
    longest = max(h - l for l, h in zip(lo, hi))
    return (eta / rho) * 0.4 / longest ** 2


def run_mantaflow(args, base_scene, res, eta, work, rep):
    tag = f"mf_r{res}_eta{eta:g}_{rep}"
    cache = os.path.join(work, tag)
    value = mantaflow_viscosity_value(base_scene, eta)
    log_path = os.path.join(work, tag + ".log")
    cmd = [args.blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", BAKE_SCRIPT,
           "--", "--res", str(res), "--frames", str(args.frames), "--viscosity-value", repr(value),
           "--cache", cache]
    code, wall, peak = run_child(cmd, log_path)
    record = {"exit_code": code, "process_wall_seconds": wall, "peak_mib": peak, "viscosity_value": value}
    result = None
    with open(log_path, "r", errors="replace") as f:
        for line in f:
            if line.startswith("MANTAFLOW_RESULT "):
                result = json.loads(line[len("MANTAFLOW_RESULT "):])
    if code != 0 or result is None:
        record["error"] = tail(log_path)
        return record
    record.update(result)
    if result.get("data_files") != args.frames:
        record["warning"] = f"{result.get('data_files')} data cache files for {args.frames} frames"
    return record


def summarize(runs, key):
    return median_or_none([r.get(key) for r in runs])


def fmt(value, spec, width):
    return f"{'—' if value is None else format(value, spec):>{width}}"


def git_state():
    try:
        rev = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return None


def main():
    args = parse_args()
    if not os.path.exists(args.viscoscope):
        sys.exit(f"{args.viscoscope} is missing: cmake --build {REPO}/build -j2 --target viscoscope")
    with open(args.scene) as f:
        base_scene = json.load(f)
    work = args.workdir or tempfile.mkdtemp(prefix="solver_vs_mantaflow_")
    os.makedirs(work, exist_ok=True)
    started = time.time()
    load_before = os.getloadavg()
    revision = git_state()  # before the runs: the tree may change while they go on
    binary_built = time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(os.path.getmtime(args.viscoscope)))

    rows = []
    try:
        for res in args.resolutions:
            for eta in args.viscosities:
                vs_runs, mf_runs = [], []
                for rep in range(args.repeat):
                    vs_runs.append(run_viscoscope(args, base_scene, res, eta, work, rep))
                    if not args.skip_mantaflow:
                        mf_runs.append(run_mantaflow(args, base_scene, res, eta, work, rep))
                rows.append(make_row(res, eta, vs_runs, mf_runs, args))
                log_progress(rows[-1], time.time() - started)
    finally:
        if not args.workdir:
            shutil.rmtree(work, ignore_errors=True)

    total = time.time() - started
    meta = {
        "benchmark": "solver_vs_mantaflow", "frames": args.frames, "fps": base_scene.get("fps", 30),
        "repeat": args.repeat, "scene": os.path.relpath(args.scene, REPO),
        "viscoscope": revision, "viscoscope_binary_built": binary_built,
        "blender": blender_version(rows),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "load_average_before": load_before, "load_average_after": os.getloadavg()},
        "total_seconds": total, "target_ratio": TARGET_RATIO,
        "viscoscope_surface_tension": (args.surface_tension if args.surface_tension is not None
                                       else base_scene["material"].get("surface_tension", 0.0)),
        "mantaflow_surface_tension": 0.0,
        "notes": [
            "Viscoscope wall = the whole `viscoscope simulate` process (start-up, scene set-up, "
            "all frames); Mantaflow wall = bpy.ops.fluid.bake_all() only (Blender start-up and "
            "scene building excluded; its per-frame cache writing is included, it cannot be off).",
            "Viscoscope output: particles, VDB and mesh off, so no surface phase runs and no files "
            "but simulation.json are written.",
            "Phase shares are of transfer+solve+other as reported in simulation.json.",
            "Peak MiB is ru_maxrss of that child process (for Mantaflow: all of Blender).",
            "Each configuration ran `repeat` times per engine; figures are medians.",
        ],
    }
    print_table(rows, meta)
    os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
    with open(args.json, "w") as f:
        json.dump({"meta": meta, "rows": rows}, f, indent=1)
    print(f"JSON: {args.json}")


def make_row(res, eta, vs_runs, mf_runs, args):
    ok_vs = [r for r in vs_runs if r.get("exit_code") == 0 and "error" not in r]
    ok_mf = [r for r in mf_runs if r.get("exit_code") == 0 and "error" not in r]
    vs_wall = summarize(ok_vs, "wall_seconds")
    mf_wall = summarize(ok_mf, "bake_seconds")
    shares = {k: median_or_none([r["phase_shares"][k] for r in ok_vs]) for k in ("transfer", "solve", "other")}
    row = {
        "resolution": res, "viscosity_pa_s": eta, "frames": args.frames,
        "viscoscope": {
            "wall_seconds": vs_wall,
            "engine_wall_seconds": summarize(ok_vs, "engine_wall_seconds"),
            "wall_per_simulated_second": summarize(ok_vs, "wall_per_simulated_second"),
            "peak_mib": summarize(ok_vs, "peak_mib"),
            "median_iterations_per_step": summarize(ok_vs, "median_iterations_per_step"),
            "steps": summarize(ok_vs, "steps"),
            "phase_shares": shares,
            "volume_drift": summarize(ok_vs, "volume_drift"),
            "all_converged": all(r.get("all_converged") for r in ok_vs) if ok_vs else None,
            "runs": vs_runs,
        },
        "mantaflow": {
            "bake_seconds": mf_wall,
            "peak_mib": summarize(ok_mf, "peak_mib"),
            "viscosity_value": mf_runs[0]["viscosity_value"] if mf_runs else None,
            "runs": mf_runs,
        },
        "ratio": (vs_wall / mf_wall) if vs_wall and mf_wall else None,
    }
    row["meets_target"] = None if row["ratio"] is None else row["ratio"] <= TARGET_RATIO
    return row


def blender_version(rows):
    for row in rows:
        for run in row["mantaflow"]["runs"]:
            if run.get("blender"):
                return run["blender"]
    return None


def log_progress(row, elapsed):
    vs, mf = row["viscoscope"], row["mantaflow"]
    problems = [r["error"].strip().splitlines()[-1] for r in vs["runs"] + mf["runs"]
                if r.get("error") and r["error"].strip()]
    problems += [r["warning"] for r in mf["runs"] if r.get("warning")]
    print(f"[{elapsed:6.0f} s] res {row['resolution']} η {row['viscosity_pa_s']:g}: "
          f"Viscoscope {fmt(vs['wall_seconds'], '.2f', 0)} s, Mantaflow {fmt(mf['bake_seconds'], '.2f', 0)} s"
          + ("; problems: " + " | ".join(problems) if problems else ""), file=sys.stderr, flush=True)


def print_table(rows, meta):
    print()
    print(f"Viscoscope vs Mantaflow — capture_cup, {meta['frames']} frames at {meta['fps']} fps, "
          f"{meta['machine']['cpus']} CPUs, load {meta['machine']['load_average_before'][0]:.2f} → "
          f"{meta['machine']['load_average_after'][0]:.2f}, Viscoscope {meta['viscoscope']}, "
          f"Blender {meta['blender']}, repeat {meta['repeat']}")
    print(f"surface tension: Viscoscope σ = {meta['viscoscope_surface_tension']:g} N/m, "
          f"Mantaflow surface_tension = {meta['mantaflow_surface_tension']:g}")
    header = (f"{'res':>4} {'η Pa·s':>7} | {'VS wall s':>9} {'s/sim s':>8} {'peak MiB':>8} {'it/step':>7} "
              f"{'transfer':>8} {'solve':>6} {'other':>6} {'vol drift':>9} | {'MF bake s':>9} {'MF MiB':>7} "
              f"{'visc_value':>10} | {'VS/MF':>6}")
    print(header)
    print("-" * len(header))
    for row in rows:
        vs, mf = row["viscoscope"], row["mantaflow"]
        sh = vs["phase_shares"]
        pct = lambda v: fmt(None if v is None else 100 * v, ".0f", 5) + "%"
        print(f"{row['resolution']:>4} {row['viscosity_pa_s']:>7g} | {fmt(vs['wall_seconds'], '.2f', 9)} "
              f"{fmt(vs['wall_per_simulated_second'], '.1f', 8)} {fmt(vs['peak_mib'], '.0f', 8)} "
              f"{fmt(vs['median_iterations_per_step'], '.0f', 7)} {pct(sh['transfer']):>8} "
              f"{pct(sh['solve']):>6} {pct(sh['other']):>6} {fmt(vs['volume_drift'], '+.2%', 9)} | "
              f"{fmt(mf['bake_seconds'], '.2f', 9)} {fmt(mf['peak_mib'], '.0f', 7)} "
              f"{fmt(mf['viscosity_value'], '.4g', 10)} | {fmt(row['ratio'], '.2f', 6)}")
    ratios = [r["ratio"] for r in rows if r["ratio"] is not None]
    if ratios:
        geo = math.exp(sum(math.log(r) for r in ratios) / len(ratios))
        met = sum(1 for r in ratios if r <= TARGET_RATIO)
        print(f"VS/MF: geometric mean {geo:.2f}, range {min(ratios):.2f}–{max(ratios):.2f}; "
              f"{met}/{len(ratios)} configurations at or below the {TARGET_RATIO} target.")
    print("VS wall = whole `viscoscope simulate` process; MF bake = bpy.ops.fluid.bake_all() only "
          "(incl. its cache writing). Surface phase off (no particle/VDB/mesh output). Phase shares are "
          "of transfer+solve+other. it/step = median over frames of Stokes iterations per step. "
          f"Each configuration run {meta['repeat']}× per engine (medians). Total {meta['total_seconds']:.0f} s.")


if __name__ == "__main__":
    main()

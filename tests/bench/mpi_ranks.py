#!/usr/bin/python3
"""`viscoscope identify` on one process with --threads N against `mpirun -n N` ranks of one thread
each, alternately in this script: the wall time of each run, the medians, their ratio, and whether
both found the same θ* and E. On one machine this measures what the ranks' messages and their
separate processes cost; on several (--hostfile) what the extra machines buy.

    mpi_ranks.py [--job JOB.json] [--ranks 2] [--repeats 3] [--hostfile HOSTS]

Without --job it identifies η on a small made-up problem (a block of liquid slumping on a 24³ grid
against hand-drawn masks, 8 generations of 4): the speed of the loop, not its answer. Under root,
Open MPI needs OMPI_ALLOW_RUN_AS_ROOT=1 and OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1, which this script sets.
"""
import argparse
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
WIDTH, HEIGHT = 96, 64


def write_small_job(folder):
    """A slumping block, a camera looking at it and two masks of it spreading to the right."""
    scene = {"format": "viscoscope.scene", "version": 1,
             "domain": {"min": [0, 0, 0], "max": [0.1, 0.04, 0.06], "resolution": 24},
             "solids": [{"type": "ground", "height": 0.0}],
             "liquids": [{"type": "box", "min": [0, 0, 0], "max": [0.035, 0.04, 0.045]}],
             "material": {"density": 1400, "viscosity": 5.0}, "fps": 30, "frames": 4, "seed": 1}
    camera = {"format": "viscoscope.camera", "version": 1, "width": WIDTH, "height": HEIGHT,
              "K": [[200, 0, 47.5], [0, 200, 25.5], [0, 0, 1]], "distortion": [0, 0, 0, 0, 0],
              "R": [[1, 0, 0], [0, 0, -1], [0, 1, 0]], "t": [-0.05, 0.03, 0.25]}
    (folder / "scene.json").write_text(json.dumps(scene))
    (folder / "camera.json").write_text(json.dumps(camera))
    masks = folder / "reference" / "masks"
    masks.mkdir(parents=True)
    frames = [2, 4]
    for frame in frames:
        pixels = bytes(255 if WIDTH * 0.2 < x < WIDTH * (0.5 + 0.05 * frame) and HEIGHT * 0.4 < y < HEIGHT * 0.75
                       else 0 for y in range(HEIGHT) for x in range(WIDTH))
        (masks / f"mask_{frame}.pgm").write_bytes(f"P5\n{WIDTH} {HEIGHT}\n255\n".encode() + pixels)
    (folder / "reference" / "manifest.json").write_text(json.dumps({
        "format": "viscoscope.reference", "version": 1, "source": "hand-drawn", "fps": 30.0,
        "width": WIDTH, "height": HEIGHT, "frames": frames, "times_s": [f / 30 for f in frames],
        "weights": [1.0, 1.0], "masks": [f"masks/mask_{f}.pgm" for f in frames]}))
    job = {"format": "viscoscope.job", "version": 1, "scene": "scene.json", "camera": "camera.json",
           "silhouettes": "reference",
           "parameters": [{"name": "viscosity", "initial": 5.0, "spread": 5.0, "min": 1e-3, "max": 1e4}],
           "resolution": 24, "max_generations": 8, "fidelity": {"coarse_generations": 1}, "seed": 4}
    (folder / "job.json").write_text(json.dumps(job))
    return folder / "job.json"


def identify(command, out):
    """Runs `command` (an identify into `out`); its wall seconds and result.json."""
    start = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if run.returncode != 0:
        sys.exit(f"mpi_ranks: {' '.join(command[:3])} … failed ({run.returncode}): {run.stderr.strip()[-500:]}")
    return seconds, json.loads((out / "result.json").read_text())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--job", type=pathlib.Path, help="a job file (default: a small made-up one)")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--hostfile", help="passed to mpirun")
    args = parser.parse_args()
    mpirun = shutil.which("mpirun")
    if not mpirun:
        sys.exit("mpi_ranks: no mpirun (Debian's mpi-default-bin)")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    with tempfile.TemporaryDirectory(prefix="mpi_ranks_") as tmp:
        tmp = pathlib.Path(tmp)
        job = args.job.resolve() if args.job else write_small_job(tmp)
        launcher = [mpirun, "--oversubscribe", "-n", str(args.ranks)]
        if args.hostfile:
            launcher += ["--hostfile", args.hostfile]
        times = {"process": [], "ranks": []}
        results = {}
        for repeat in range(args.repeats):
            for name in times:
                out = tmp / f"{name}_{repeat}"
                threads = str(args.ranks) if name == "process" else "1"
                command = [args.engine, "identify", str(job), "--out", str(out), "--progress", "none",
                           "--no-plots", "--no-fields", "--threads", threads]
                if name == "ranks":
                    command = launcher + command
                seconds, results[name] = identify(command, out)
                times[name].append(seconds)
                print(f"  {name:7s} run {repeat + 1}: {seconds:7.2f} s", flush=True)
        same = all(results["process"][key] == results["ranks"][key] for key in ("E", "evaluations")) and all(
            results["process"]["viscosity"][key] == results["ranks"]["viscosity"][key] for key in ("value", "interval"))
        process, ranks = statistics.median(times["process"]), statistics.median(times["ranks"])
        print(f"{results['ranks']['evaluations']} evaluations: one process on {args.ranks} threads {process:.2f} s, "
              f"{args.ranks} ranks of 1 thread {ranks:.2f} s (medians of {args.repeats}); ranks / process "
              f"{ranks / process:.3f}; same θ* and E: {same}")


if __name__ == "__main__":
    main()

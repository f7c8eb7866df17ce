#!/usr/bin/python3
r"""What the hole calibration's disk cache saves a `simulate` of the sample cup (issue 85).

For each resolution and trial, the same scene (`sample_scenes/capture_cup.json`, η = 8 Pa·s, a few
frames) is simulated twice into fresh folders with a fresh calibration cache
(VISCOSCOPE_CACHE_DIR): the first run calibrates the hole and stores it, the second reads it.
Prints each run's wall seconds (the engine's own `wall_seconds`), the calibration's solves, the
ratio second/first, and whether the two runs' particles are byte for byte the same; medians over
the trials.

    /usr/bin/python3 tests/bench/calibration_cache.py [--resolutions 48 64 96] [--frames 2] [--trials 3]
"""
import argparse
import filecmp
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]


def simulate(engine, scene_file, out, cache):
    """simulation.json of one run of `scene_file` into `out` with the calibration cache `cache`."""
    result = subprocess.run([str(engine), "simulate", str(scene_file), "--out", str(out), "--progress", "none"],
                            capture_output=True, text=True, env=dict(os.environ, VISCOSCOPE_CACHE_DIR=str(cache)))
    if result.returncode != 0:
        sys.exit(f"simulate failed: {result.stderr.strip()}")
    return json.loads((out / "simulation.json").read_text())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--resolutions", type=int, nargs="+", default=[48, 64, 96])
    parser.add_argument("--frames", type=int, default=2)
    parser.add_argument("--trials", type=int, default=3)
    args = parser.parse_args()
    scene = json.loads((ROOT / "sample_scenes/capture_cup.json").read_text())
    scene["frames"] = args.frames
    scene["output"] = {"particles": True, "vdb": False, "mesh": False}
    print("resolution  first (s)  solves  second (s)  solves  second/first  same particles")
    for resolution in args.resolutions:
        scene["domain"]["resolution"] = resolution
        firsts, seconds, same = [], [], True
        for trial in range(args.trials):
            with tempfile.TemporaryDirectory(prefix="viscoscope_cache_bench_") as tmp:
                work = pathlib.Path(tmp)
                (work / "scene.json").write_text(json.dumps(scene))
                runs = [simulate(args.engine, work / "scene.json", work / name, work / "cache") for name in ("a", "b")]
                firsts.append(runs[0]["wall_seconds"])
                seconds.append(runs[1]["wall_seconds"])
                solves = [run["hole_calibrations"][0]["solves"] for run in runs]
                frames = sorted(p.name for p in (work / "a").glob("particles_*.bin"))
                same &= all(filecmp.cmp(work / "a" / name, work / "b" / name, shallow=False) for name in frames)
                print(f"{resolution:10d}  {firsts[-1]:9.1f}  {solves[0]:6d}  {seconds[-1]:10.1f}  {solves[1]:6d}  "
                      f"{seconds[-1] / firsts[-1]:12.2f}  {'yes' if same else 'NO'}", flush=True)
        print(f"{resolution:10d}  median {statistics.median(firsts):.1f} s → {statistics.median(seconds):.1f} s, "
              f"ratio {statistics.median(s / f for s, f in zip(seconds, firsts)):.2f}", flush=True)


if __name__ == "__main__":
    main()

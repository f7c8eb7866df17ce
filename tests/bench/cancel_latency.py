#!/usr/bin/python3
r"""How long the engine takes to stop after SIGTERM, in each phase a long run passes through.

Each trial starts a command, waits until it is inside the phase (by its progress lines, or from
the start for the phases that print none), sends SIGTERM at a random moment within the phase's
span after that and times the exit. It
prints, per phase and engine, the median and worst latency and the exit codes seen (3 = cancelled).
Give --before an older engine to time both side by side in one run.

Phases:
  hole calibration  the sample cup at 96³: the calibration's steady solves run before any frame
  frame             the sample cup at 48³, inside a frame after the first two
  mesh set-up       a 1.3-million-triangle mesh solid at 128³: reading it (98 MB of OBJ), voxelising
                    it, sampling the solids and seeding the liquid, which take about 20 s
  generation        an identification of a slumping block at 24³, inside its second generation

    /usr/bin/python3 tests/bench/cancel_latency.py --trials 5 --before /tmp/ci/build/bin/viscoscope
"""
import argparse
import json
import math
import os
import pathlib
import random
import signal
import statistics
import subprocess
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
MAX_WAIT = 900  # s a trial may take in all; an engine that ignores SIGTERM is killed after it


def sample_scene(resolution, frames):
    scene = json.loads((ROOT / "sample_scenes/capture_cup.json").read_text())
    scene["domain"]["resolution"] = resolution
    scene["frames"] = frames
    scene["output"] = {"particles": False, "vdb": False, "mesh": False}
    return scene


def sphere_obj(path, rings):
    """A closed UV sphere of radius 3 cm at the domain's centre, rings × 2 rings triangles a ring."""
    lines = []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(2 * rings):
            phi = math.pi * j / rings
            lines.append("v %.6f %.6f %.6f" % (0.03 * math.sin(theta) * math.cos(phi),
                                                0.03 * math.sin(theta) * math.sin(phi), 0.09 + 0.03 * math.cos(theta)))
    for i in range(rings):
        for j in range(2 * rings):
            a, b = i * 2 * rings + j + 1, i * 2 * rings + (j + 1) % (2 * rings) + 1
            c, d = a + 2 * rings, b + 2 * rings
            lines.append("f %d %d %d" % (a, c, b))
            lines.append("f %d %d %d" % (b, c, d))
    path.write_text("\n".join(lines) + "\n")


def mesh_scene(work):
    sphere_obj(work / "sphere.obj", 800)
    scene = sample_scene(128, 1)
    scene["solids"] = [{"type": "ground", "height": 0.0}, {"type": "mesh", "path": str(work / "sphere.obj")}]
    scene["liquids"] = [{"type": "box", "min": [-0.02, -0.02, 0.13], "max": [0.02, 0.02, 0.15]}]
    return scene


def identify_job(work):
    """A block slumping on the ground, and hand-drawn masks of it spreading, as cli_identify_test has."""
    scene = {"format": "viscoscope.scene", "version": 1,
             "domain": {"min": [0, 0, 0], "max": [0.1, 0.04, 0.06], "resolution": 24},
             "solids": [{"type": "ground", "height": 0.0}],
             "liquids": [{"type": "box", "min": [0, 0, 0], "max": [0.035, 0.04, 0.045]}],
             "material": {"density": 1400, "viscosity": 5.0}, "fps": 30, "frames": 30, "seed": 1}
    (work / "scene.json").write_text(json.dumps(scene))
    camera = {"format": "viscoscope.camera", "version": 1, "width": 96, "height": 64,
              "K": [[200, 0, 47.5], [0, 200, 25.5], [0, 0, 1]], "distortion": [0, 0, 0, 0, 0],
              "R": [[1, 0, 0], [0, 0, -1], [0, 1, 0]], "t": [-0.05, 0.03, 0.25]}
    (work / "camera.json").write_text(json.dumps(camera))
    (work / "reference/masks").mkdir(parents=True)
    frames = list(range(5, 31, 5))
    for frame in frames:
        pixels = bytes(255 if 96 * 0.2 < x < 96 * (0.45 + 0.01 * frame) and 64 * 0.4 < y < 64 * 0.75 else 0
                       for y in range(64) for x in range(96))
        (work / f"reference/masks/mask_{frame}.pgm").write_bytes(b"P5\n96 64\n255\n" + pixels)
    manifest = {"format": "viscoscope.reference", "version": 1, "source": "hand-drawn", "fps": 30.0,
                "width": 96, "height": 64, "frames": frames, "times_s": [f / 30 for f in frames],
                "weights": [1.0] * len(frames), "masks": [f"masks/mask_{f}.pgm" for f in frames]}
    (work / "reference/manifest.json").write_text(json.dumps(manifest))
    job = {"format": "viscoscope.job", "version": 1, "scene": "scene.json", "camera": "camera.json",
           "video": None, "silhouettes": "reference", "frame_start": 1, "frame_end": 250,
           "parameters": [{"name": "viscosity", "initial": 5.0, "spread": 3.0, "min": 0.1, "max": 100, "log": True}],
           "resolution": 24, "max_generations": 20, "fidelity": {"coarse_generations": 1}, "seed": 4}
    (work / "job.json").write_text(json.dumps(job))
    return work / "job.json"


def inside_frame(event):
    return event.get("event") == "progress" and event.get("frame", 0) >= 2


def inside_second_generation(event):
    return event.get("event") == "progress" and event.get("generation", 0) >= 1


PHASES = {
    # name: (make the command's arguments in `work`, the progress line that says the phase is running or
    #        None to count from the start, the span (s) after it within which the signal comes)
    "hole calibration": (lambda work: ["simulate", write(work, sample_scene(96, 1)), "--out", str(work / "out")],
                         None, (1.0, 30.0)),
    "frame": (lambda work: ["simulate", write(work, sample_scene(48, 60)), "--out", str(work / "out")],
              inside_frame, (0.0, 1.0)),
    "mesh set-up": (lambda work: ["simulate", write(work, mesh_scene(work)), "--out", str(work / "out")],
                    None, (1.0, 20.0)),
    "generation": (lambda work: ["identify", str(identify_job(work)), "--out", str(work / "out"), "--no-plots",
                                 "--no-fields"], inside_second_generation, (0.0, 2.0)),
}


def write(work, scene):
    (work / "scene.json").write_text(json.dumps(scene))
    return str(work / "scene.json")


def trial(engine, phase, rng):
    """Seconds from SIGTERM to exit, and the exit code (None: it ended before the signal)."""
    command, ready, span = PHASES[phase]
    with tempfile.TemporaryDirectory(prefix="viscoscope_cancel_") as tmp:
        work = pathlib.Path(tmp)
        # Each trial's own calibration cache, so that the hole calibration's solves run every time.
        env = dict(os.environ, VISCOSCOPE_CACHE_DIR=str(work / "cache"))
        process = subprocess.Popen([str(engine)] + command(work) + ["--progress", "json"], stdout=subprocess.PIPE,
                                   stderr=subprocess.DEVNULL, text=True, env=env)
        start = time.monotonic()
        if ready is not None:
            for line in process.stdout:
                try:
                    if ready(json.loads(line)):
                        break
                except json.JSONDecodeError:
                    pass
        time.sleep(rng.uniform(*span))
        if process.poll() is not None:
            return None, process.returncode
        process.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        try:
            process.communicate(timeout=max(1.0, MAX_WAIT - (sent - start)))
        except subprocess.TimeoutExpired:
            process.kill()
            process.communicate()
            return math.inf, "killed"
        return time.monotonic() - sent, process.returncode


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--before", type=pathlib.Path, help="an older engine, timed in the same run")
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--phases", default=",".join(PHASES))
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    engines = [("this", args.engine)] + ([("before", args.before)] if args.before else [])
    rng = random.Random(args.seed)
    print("%-17s %-7s %9s %9s  %s" % ("phase", "engine", "median s", "worst s", "exit codes"))
    for phase in args.phases.split(","):
        for label, engine in engines:
            latencies, codes = [], []
            for _ in range(args.trials):
                latency, code = trial(engine, phase, rng)
                codes.append(code)
                if latency is not None:
                    latencies.append(latency)
            median = statistics.median(latencies) if latencies else math.nan
            worst = max(latencies) if latencies else math.nan
            print("%-17s %-7s %9.2f %9.2f  %s" % (phase, label, median, worst, codes), flush=True)


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Two engine builds simulating the same scene, alternately in this script: the wall time of each
`viscoscope simulate` run, the medians, and their ratio. For measuring a change to the engine
against the build before it; the runs alternate so that the machine's drift hits both alike.

    engine_ab.py --before OLD/viscoscope --after build/bin/viscoscope [--scene sample_scenes/capture_cup.json]
                 [--eta 300] [--model '{"type": "power_law", ...}'] [--resolution 48] [--frames 40] [--repeats 3]
"""
import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="the engine to compare against")
    parser.add_argument("--after", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--scene", default=str(ROOT / "sample_scenes/capture_cup.json"))
    parser.add_argument("--eta", type=float, default=None, help="viscosity, Pa·s (default: the scene's)")
    parser.add_argument("--model", help="the liquid's material.model (JSON), e.g. a power law")
    parser.add_argument("--resolution", type=int, default=None)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    for engine in (args.before, args.after):
        if not pathlib.Path(engine).is_file():
            sys.exit(f"engine_ab: no engine at {engine}")

    scene = json.loads(pathlib.Path(args.scene).read_text())
    if args.eta is not None:
        scene["material"]["viscosity"] = args.eta
    if args.model is not None:
        scene["material"]["model"] = json.loads(args.model)
    if args.resolution is not None:
        scene["domain"]["resolution"] = args.resolution
    scene["frames"] = args.frames
    scene["output"] = {"particles": False, "vdb": False, "mesh": False}
    seconds = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as work:
        scene_file = pathlib.Path(work) / "scene.json"
        scene_file.write_text(json.dumps(scene))
        for repeat in range(args.repeats):
            for name, engine in (("before", args.before), ("after", args.after)):
                start = time.monotonic()
                # A fresh directory each run: `simulate` keeps a completed run of the same scene
                # by the same build and would return at once.
                out = pathlib.Path(work) / f"{name}_{repeat}"
                subprocess.run([engine, "simulate", str(scene_file), "--out", str(out), "--progress", "none"],
                               check=True)
                seconds[name].append(time.monotonic() - start)
                print(f"repeat {repeat + 1} {name:6s} {seconds[name][-1]:7.2f} s", flush=True)
    before, after = statistics.median(seconds["before"]), statistics.median(seconds["after"])
    print(f"{pathlib.Path(args.scene).name} η {scene['material']['viscosity']} Pa·s"
          f"{', model ' + args.model if args.model else ''}, "
          f"{scene['domain']['resolution']}³, {args.frames} frames: median before {before:.2f} s, "
          f"after {after:.2f} s, after/before {after / before:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

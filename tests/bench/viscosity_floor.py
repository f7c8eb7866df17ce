#!/usr/bin/python3
"""Below which viscosity can the solver no longer tell viscosities apart, per grid resolution?

APIC and the grid carry a numerical viscosity of order Δx²/Δt. This benchmark simulates the sample
capture scene at several η and resolutions and prints the drained fraction of the liquid (particles
below the cup's bottom) after --frames frames. Where neighbouring η give the same drained fraction
within the seed-to-seed scatter, the solver cannot distinguish them at that resolution.

    /usr/bin/python3 tests/bench/viscosity_floor.py [--resolutions 32 48 64] [--frames 20]
"""
import argparse
import json
import pathlib
import struct
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]


def read_particles(path):
    data = path.read_bytes()
    assert data[:4] == b"VSCP", path
    (count,) = struct.unpack_from("<Q", data, 8)
    return np.frombuffer(data, dtype="<f4", count=6 * count, offset=16).reshape(count, 6)


def simulate(engine, scene, work, what):
    """Writes `scene` to work/scene.json and simulates it into work/out; on failure exits with one
    line naming `what` ran."""
    work.mkdir()
    (work / "scene.json").write_text(json.dumps(scene), encoding="utf-8")
    result = subprocess.run([str(engine), "simulate", str(work / "scene.json"), "--out", str(work / "out"),
                             "--progress", "none"], capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"simulate failed at {what}: {result.stderr.strip()}")
    return work / "out"


def scene_variant(base, resolution, viscosity, frames, seed, particles_per_cell=None, surface_tension=None,
                  vdb=False):
    """A copy of the scene `base` on another grid, seeding, liquid and clip, writing its particles (and
    surfaces with `vdb`); also its cell size (m). None keeps the scene's value."""
    scene = json.loads(json.dumps(base))
    scene["domain"]["resolution"] = resolution
    scene["material"]["viscosity"] = viscosity
    if surface_tension is not None:
        scene["material"]["surface_tension"] = surface_tension
    scene["frames"], scene["seed"] = frames, seed
    if particles_per_cell is not None:
        scene.setdefault("solver", {})["particles_per_cell"] = particles_per_cell
    scene["output"] = {"particles": True, "vdb": vdb, "mesh": False}
    cell = max(hi - lo for lo, hi in zip(scene["domain"]["min"], scene["domain"]["max"])) / resolution
    return scene, cell


def drained_fraction(engine, scene, resolution, eta, frames, seed):
    scene, _ = scene_variant(scene, resolution, eta, frames, seed)
    cup = next(s for s in scene["solids"] if s["type"] == "cup")
    with tempfile.TemporaryDirectory() as tmp:
        out = simulate(engine, scene, pathlib.Path(tmp) / "run", f"{resolution} cells, η {eta:g}, seed {seed}")
        p = read_particles(out / f"particles_{frames:05d}.bin")
    return float(np.mean(p[:, 2] < cup["position"][2]))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[32, 48])
    parser.add_argument("--viscosities", type=float, nargs="+", default=[0.01, 0.1, 0.3, 1, 3, 10])
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    args = parser.parse_args()
    scene = json.loads((ROOT / "sample_scenes/capture_cup.json").read_text())
    print(f"drained fraction after {args.frames} frames (seed 1 / seed 2)")
    print("res  " + "  ".join(f"η={eta:<8g}" for eta in args.viscosities))
    for res in args.resolutions:
        row = []
        for eta in args.viscosities:
            a = drained_fraction(args.engine, scene, res, eta, args.frames, 1)
            b = drained_fraction(args.engine, scene, res, eta, args.frames, 2)
            row.append(f"{a:.3f}/{b:.3f}")
        print(f"{res:<4} " + "  ".join(f"{r:<10}" for r in row), flush=True)


if __name__ == "__main__":
    main()

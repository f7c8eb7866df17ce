#!/usr/bin/python3
r"""How fast the sample cup's first liquid falls from its hole, by grid, particles and surface tension.

The sample cup (sample_scenes/capture_cup.json) is simulated at --viscosity for --frames frames
with the built engine: at --peer-resolution with 8 particles per cell (the Table 1 references'
grid and seeding) and at --resolutions with 8 and 27, each with the scene's surface tension and
without it. Per frame it prints the lowest particle within 1 cm of the cup's axis (the tip of the
liquid leaving the hole) and how far it trails the peer's with the same surface tension, and the
liquid below the cup's bottom (its particles' count × volume) as a ratio to the peer's. The
first frames carry most of what an identification learns at low η: while the tip falls, the
silhouettes of neighbouring η differ most. A grid whose outflow matches the peer's but whose tip
trails it holds its thread back, and an identification fitting it picks a lower η.

    /usr/bin/python3 tests/bench/tip_descent.py
    /usr/bin/python3 tests/bench/tip_descent.py --viscosity 10 --frames 9 --resolutions 48
"""
import argparse
import json
import pathlib
import tempfile

import numpy as np

from viscosity_floor import read_particles, scene_variant, simulate  # beside this script

ROOT = pathlib.Path(__file__).resolve().parents[2]
AXIS_RADIUS = 0.01  # m: the tip is looked for this close to the cup's axis


def descent(out, frames, cup, particle_volume):
    """Per frame 1..frames: the tip's height (m) and the liquid below the cup's bottom (m³)."""
    tips, below = [], []
    for frame in range(1, frames + 1):
        positions = read_particles(out / f"particles_{frame:05d}.bin")[:, :3].astype(float)
        near = np.hypot(positions[:, 0] - cup["position"][0], positions[:, 1] - cup["position"][1]) < AXIS_RADIUS
        tips.append(positions[near, 2].min() if near.any() else float("nan"))
        below.append(particle_volume * np.count_nonzero(positions[:, 2] < cup["position"][2]))
    return np.array(tips), np.array(below)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--scene", default=ROOT / "sample_scenes/capture_cup.json", type=pathlib.Path)
    parser.add_argument("--resolutions", type=int, nargs="+", default=[48, 64])
    parser.add_argument("--peer-resolution", type=int, default=96)
    parser.add_argument("--viscosity", type=float, default=3.0)
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--peer-seed", type=int, default=11)
    args = parser.parse_args()
    if args.frames < 1:
        parser.error("--frames must be at least 1")

    base = json.loads(args.scene.read_text(encoding="utf-8"))
    cup = next(s for s in base["solids"] if s["type"] == "cup")
    sigma = base["material"].get("surface_tension", 0.0)
    runs = [(args.peer_resolution, 8, args.peer_seed)] + [
        (resolution, per_cell, args.seed) for resolution in args.resolutions for per_cell in (8, 27)]
    print(f"sample cup at η {args.viscosity:g} Pa·s, frames 1..{args.frames}: lowest particle within "
          f"{100 * AXIS_RADIUS:g} cm of the axis (mm), its lag behind the {args.peer_resolution}³ peer's (mm, "
          "cells), liquid below the cup / peer's", flush=True)
    with tempfile.TemporaryDirectory(prefix="tip_descent_") as tmp:
        for surface_tension in (sigma, 0.0):
            print(f"surface tension {surface_tension:g} N/m")
            peer = None
            for resolution, per_cell, seed in runs:
                scene, cell = scene_variant(base, resolution, args.viscosity, args.frames, seed, per_cell,
                                            surface_tension)
                what = f"{resolution} cells, {per_cell} per cell, surface tension {surface_tension:g}"
                out = simulate(args.engine, scene, pathlib.Path(tmp) / f"{resolution}_{per_cell}_{surface_tension:g}", what)
                tips, below = descent(out, args.frames, cup, cell ** 3 / per_cell)
                if peer is None:
                    peer = tips, below
                lag = tips - peer[0]
                print(f"  {resolution:4d}³ {per_cell:2d} per cell  tip " + " ".join(f"{1000 * z:6.1f}" for z in tips) +
                      "  lag " + " ".join(f"{1000 * d:5.1f}" for d in lag) +
                      f"  (frame {args.frames}: {lag[-1] / cell:+.2f} cells)  below / peer's " +
                      " ".join(f"{b / p:.3f}" if p > 0 else "n/a" for b, p in zip(below, peer[1])), flush=True)


if __name__ == "__main__":
    main()

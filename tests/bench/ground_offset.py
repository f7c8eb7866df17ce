#!/usr/bin/python3
r"""How a puddle's spreading depends on where the ground sits between two rows of z-faces.

A block of liquid (50 × 50 × 20 mm) slumps on a ground placed at fractions of a cell above the face
below it, and is simulated with the built engine at --resolution and, as the peer, at
--peer-resolution (the domain, 180 × 180 × 45 mm, stays the same). For each run it prints, at the
last frame, the puddle's rms radius (over all particles: the bulk's spreading) and its foot (the
99.5th percentile of the distance from the axis of the particles within 3 mm of the ground), and
their ratios to the peer's mean. A wall condition that the discretization gets right makes both
independent of the offset. The solver has two regimes: below ½ the lowest x- and y-faces lie above
the ground and are unknowns whose ghost across it puts the wall where it is (wallGhostRatio, which
floors the face's distance at 0.1 cell); from ½ on they lie inside it and are shut.

    /usr/bin/python3 tests/bench/ground_offset.py
    /usr/bin/python3 tests/bench/ground_offset.py --offsets 0.4,0.45,0.48,0.5 --surface-tension 0
"""
import argparse
import json
import pathlib
import statistics
import tempfile

import numpy as np

from viscosity_floor import read_particles, simulate  # beside this script

ROOT = pathlib.Path(__file__).resolve().parents[2]
DOMAIN_MIN, DOMAIN_MAX = [-0.09, -0.09, 0.0], [0.09, 0.09, 0.045]
BLOCK_HALF_WIDTH, BLOCK_HEIGHT = 0.025, 0.02  # m
FOOT_BAND = 0.003  # m above the ground


def slump_scene(resolution, offset, args):
    """The block on a ground `offset` cells above the domain's floor face (the grid is not moved:
    sim::sceneGrid only moves it for cups with a hole)."""
    ground = offset * (DOMAIN_MAX[0] - DOMAIN_MIN[0]) / resolution
    return {"format": "viscoscope.scene", "version": 1,
            "domain": {"min": DOMAIN_MIN, "max": DOMAIN_MAX, "resolution": resolution},
            "solids": [{"type": "ground", "height": ground}],
            "liquids": [{"type": "box", "min": [-BLOCK_HALF_WIDTH, -BLOCK_HALF_WIDTH, ground],
                         "max": [BLOCK_HALF_WIDTH, BLOCK_HALF_WIDTH, ground + BLOCK_HEIGHT]}],
            "material": {"density": 1400, "viscosity": args.viscosity, "surface_tension": args.surface_tension},
            "gravity": [0, 0, -9.81], "fps": 30, "frames": args.frames, "seed": args.seed,
            "output": {"particles": True, "vdb": False, "mesh": False}}, ground


def spread(particles_file, ground):
    """(rms radius, foot radius) in mm of the particles in a "VSCP" file."""
    positions = read_particles(particles_file)[:, :3].astype(float)
    radius = np.hypot(positions[:, 0], positions[:, 1])
    foot = radius[positions[:, 2] < ground + FOOT_BAND]
    return 1000 * float(np.sqrt(np.mean(radius ** 2))), 1000 * float(np.percentile(foot, 99.5))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--resolution", type=int, default=48)
    parser.add_argument("--offsets", default="0,0.15,0.31,0.4,0.45,0.48,0.5,0.55,0.66,0.85",
                        help="ground heights above the face below, in cells of --resolution")
    parser.add_argument("--peer-resolution", type=int, default=96)
    parser.add_argument("--peer-offsets", default="0,0.6", help="in cells of --peer-resolution")
    parser.add_argument("--viscosity", type=float, default=1.0)
    parser.add_argument("--surface-tension", type=float, default=0.07)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()

    print(f"slump of a {2000 * BLOCK_HALF_WIDTH:.0f} × {2000 * BLOCK_HALF_WIDTH:.0f} × {1000 * BLOCK_HEIGHT:.0f} mm "
          f"block, η {args.viscosity:g} Pa·s, σ {args.surface_tension:g} N/m, frame {args.frames}; rms radius and "
          f"foot (mm), and their ratios to the {args.peer_resolution}³ peer's mean", flush=True)
    runs = {}
    with tempfile.TemporaryDirectory(prefix="ground_offset_") as tmp:
        for resolution, offsets in [(args.peer_resolution, args.peer_offsets), (args.resolution, args.offsets)]:
            for offset in [float(o) for o in offsets.split(",")]:
                scene, ground = slump_scene(resolution, offset, args)
                out = simulate(args.engine, scene, pathlib.Path(tmp) / f"{resolution}_{offset}",
                               f"{resolution} cells, ground offset {offset}")
                runs[resolution, offset] = spread(out / f"particles_{args.frames:05d}.bin", ground)
    peer = [v for (r, _), v in runs.items() if r == args.peer_resolution]
    peer_rms = statistics.fmean(v[0] for v in peer)
    peer_foot = statistics.fmean(v[1] for v in peer)
    for (resolution, offset), (rms, foot) in runs.items():
        print(f"  {resolution:4d} cells, ground {offset:5.3f} cell above the face below: rms {rms:6.2f} "
              f"({rms / peer_rms:.3f}), foot {foot:6.2f} ({foot / peer_foot:.3f})")
    coarse = [v for (r, _), v in runs.items() if r == args.resolution]
    for name, column in [("rms", 0), ("foot", 1)]:
        values = [v[column] for v in coarse]
        print(f"{args.resolution} cells: {name} spread over the offsets {max(values) / min(values) - 1:+.1%}")


if __name__ == "__main__":
    main()

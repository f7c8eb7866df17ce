#!/usr/bin/python3
r"""How the sample cup's drain depends on where the cup sits against the grid.

The cup of sample_scenes/capture_cup.json is moved by fractions of a cell (upwards, sideways along
x, or along x and y at once) and simulated at several grids with the built engine; for each run the
share of particles below the cup's bottom at the given frames is printed (and the stream's tip, its
lowest particle's height, and the puddle's reach, the 99th percentile of the distance from the cup's
axis of the particles within 20 mm of the ground, both in mm), with the spread over the shifts
(max/min − 1) per grid and the ratio of the grids' means. A drain that the discretization gets
right does not depend on the shift, and agrees between grids. Each grid runs with every hole
conductance of --conductances (see `hole_conductance` in the README): "dagan" (the calibrated drag,
the default) and/or "grid".

    /usr/bin/python3 tests/bench/drain_alignment.py --resolutions 48,64 --frames 10,30
    /usr/bin/python3 tests/bench/drain_alignment.py --resolutions 48,64,96,128 --shifts 0,0.5 --axis xy \
        --viscosity 1 --frames 8
    /usr/bin/python3 tests/bench/drain_alignment.py --resolutions 48,96,128 --shifts 0 --viscosity 1 \
        --frames 4,8 --conductances dagan,grid
"""
import argparse
import itertools
import json
import pathlib
import statistics
import tempfile

import numpy as np

from viscosity_floor import read_particles, simulate  # beside this script

ROOT = pathlib.Path(__file__).resolve().parents[2]


def drained_share_tip_and_reach(particles_file, bottom_z, axis_xy, ground_z):
    """Share of the particles in a "VSCP" file whose height is below bottom_z, the lowest height, and
    the 99th percentile of the distance from axis_xy of those within 20 mm of ground_z (0: none)."""
    positions = read_particles(particles_file)[:, :3]
    heights = positions[:, 2]
    near_ground = positions[heights < ground_z + 0.02]
    reach = np.percentile(np.hypot(*(near_ground[:, :2] - axis_xy).T), 99) if len(near_ground) else 0.0
    return float((heights < bottom_z).mean()), float(heights.min()), float(reach)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--scene", default=ROOT / "sample_scenes/capture_cup.json", type=pathlib.Path)
    parser.add_argument("--resolutions", default="48,64,80")
    parser.add_argument("--shifts", default="0,0.25,0.5,0.75", help="cup shifts in cells")
    parser.add_argument("--axis", default="xy", choices=["x", "y", "z", "xy"],
                        help="the axes the cup moves along (along z the grid follows its underside: sim::sceneGrid)")
    parser.add_argument("--frames", default="10", help="frames at which the drained share is read")
    parser.add_argument("--viscosity", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--conductances", default="dagan", help="hole conductances, comma-separated: dagan, grid")
    args = parser.parse_args()

    base = json.loads(args.scene.read_text(encoding="utf-8"))
    cup = next(s for s in base["solids"] if s["type"] == "cup")
    extent = max(hi - lo for lo, hi in zip(base["domain"]["min"], base["domain"]["max"]))
    frames = [int(f) for f in args.frames.split(",")]
    shifts = [float(s) for s in args.shifts.split(",")]
    axes = ["xyz".index(a) for a in args.axis]
    resolutions = [int(r) for r in args.resolutions.split(",")]
    conductances = args.conductances.split(",")

    ground = next((s["height"] for s in base["solids"] if s["type"] == "ground"), base["domain"]["min"][2])
    print(f"eta {args.viscosity} Pa·s, seed {args.seed}, cup shifted along {args.axis}; drained share "
          f"(and tip, puddle's reach, mm) at frames {frames}")
    means = {}
    with tempfile.TemporaryDirectory(prefix="drain_alignment_") as tmp:
        for resolution, conductance in itertools.product(resolutions, conductances):
            grid = f"{resolution}³ {conductance}"
            dx = extent / resolution
            shares = {f: [] for f in frames}
            for shift in shifts:
                scene = json.loads(json.dumps(base))
                moved = next(s for s in scene["solids"] if s["type"] == "cup")
                for axis in axes:
                    moved["position"][axis] = cup["position"][axis] + shift * dx
                scene.update(seed=args.seed, frames=max(frames),
                             output={"particles": True, "vdb": False, "mesh": False})
                scene["domain"]["resolution"] = resolution
                scene["material"]["viscosity"] = args.viscosity
                scene.setdefault("solver", {})["hole_conductance"] = conductance
                out = simulate(args.engine, scene, pathlib.Path(tmp) / f"{resolution}_{conductance}_{shift}",
                               f"{grid}, shift {shift}")
                bottom = moved["position"][2]
                row = []
                for f in frames:
                    share, tip, reach = drained_share_tip_and_reach(
                        out / f"particles_{f:05d}.bin", bottom, moved["position"][:2], ground)
                    shares[f].append(share)
                    row.append(f"{share:.4f} (tip {1000 * tip:.1f}, puddle {1000 * reach:.1f})")
                print(f"  {grid} shift {shift:4.2f}: " + " ".join(row), flush=True)
            for f in frames:
                mean = statistics.fmean(shares[f])
                means.setdefault(f, {})[grid] = mean
                print(f"{grid} frame {f}: mean {mean:.4f}, spread {max(shares[f]) / min(shares[f]) - 1:+.1%}")
    finest = f"{max(resolutions)}³ {conductances[0]}"  # what the ratios are against
    for f in frames:
        if len(means[f]) < 2:
            continue
        ratios = ", ".join(f"{g} / {finest} {m / means[f][finest]:.3f}" for g, m in means[f].items() if g != finest)
        print(f"frame {f}: ratio of means {ratios}")


if __name__ == "__main__":
    main()

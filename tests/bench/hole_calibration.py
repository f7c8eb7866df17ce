#!/usr/bin/python3
r"""The hole calibration's own box on finer and finer lattices: where its steady flux converges.

The hole's drag (HoleCalibration in native/src/sim/sim.h) is sized so that the steady Stokes flux
of its box (a layer 4 hole radii deep over the cup's bottom, periodic across x and y, with a jet as
long hanging from the hole into air) equals sim::kFreeJetFluxOverDagan × Dagan, Weinbaum &
Pfeffer's orifice flux for the same drop. That constant is the flux the box's faces converge to as
the lattice refines, which this benchmark measures: each run simulates a tiny scene holding the
sample cup's bottom (hole radius 9 mm, 5 mm thick) at the given Δx, whose set-up calibrates the
hole, and reads the faces' flux without the drag (`grid_flux_vs_dagan`). A placement "s:u" moves
the cup s cells along x and y and u cells above a row of z-faces; the flux depends on it by some
percent, so each lattice prints the placements' mean, and the means are fitted linearly in Δx,
the error of a hole cut from whole faces being first order.

Each run calibrates the hole in full (2–4 steady solves; run with VISCOSCOPE_CACHE_DIR= to keep
the engine from taking a calibration it stored before): at 48 and 64 all eight runs took 2 min,
one run at 96 about 3 min, both while the machine ran other work.

    /usr/bin/python3 tests/bench/hole_calibration.py --resolutions 48,64
    /usr/bin/python3 tests/bench/hole_calibration.py --resolutions 96,128,160
"""
import argparse
import json
import math
import pathlib
import statistics
import sys
import tempfile

import numpy as np

from orifice_flux import parse_grids_and_placements  # beside this script
from viscosity_floor import simulate

ROOT = pathlib.Path(__file__).resolve().parents[2]
HEIGHT = 0.18                # the sample scene's domain height: a resolution here is its 48³, 96³, …
HOLE, THICKNESS = 0.009, 0.005  # the sample cup's, m


def scene(resolution, sideways, up):
    dx = HEIGHT / resolution
    bottom = (2 + up) * dx
    # A few cells around the hole suffice: the calibration builds its own box on this lattice. The
    # plate and a layer of liquid over it must fit (from 128 on, 6 cells are thinner than the plate).
    tall = max(6, math.ceil((bottom + THICKNESS) / dx) + 2)
    return {"format": "viscoscope.scene", "version": 1,
            "domain": {"min": [-2 * dx, -2 * dx, 0], "max": [2 * dx, 2 * dx, tall * dx], "resolution": tall},
            "solids": [{"type": "cup", "position": [sideways * dx, sideways * dx, bottom],
                        "inner_radius": 0.043, "height": 0.05, "wall_thickness": 0.006,
                        "bottom_thickness": THICKNESS, "hole_radius": HOLE}],
            "liquids": [{"type": "box", "min": [-2 * dx, -2 * dx, bottom + THICKNESS],
                         "max": [2 * dx, 2 * dx, tall * dx]}],
            "material": {"density": 1400, "viscosity": 10.0, "surface_tension": 0.0},
            "gravity": [0, 0, -9.81], "fps": 1000, "frames": 1, "seed": 3,
            "output": {"particles": False, "vdb": False, "mesh": False}}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--resolutions", default="48,64",
                        help="comma-separated cells along the sample scene's 180 mm height")
    parser.add_argument("--placements", default="0:0.25,0.5:0.75,0:0.75,0.5:0.25",
                        help="comma-separated s:u, the cup moved s cells along x and y and u cells up")
    args = parser.parse_args()
    resolutions, placements = parse_grids_and_placements("hole_calibration", args.resolutions, args.placements)
    if not resolutions or min(resolutions) < 8:
        sys.exit("hole_calibration: --resolutions must be integers of at least 8")

    means = []
    with tempfile.TemporaryDirectory(prefix="hole_calibration_") as tmp:
        for resolution in resolutions:
            fluxes = []
            for sideways, up in placements:
                out = simulate(args.engine, scene(resolution, sideways, up),
                               pathlib.Path(tmp) / f"{resolution}_{sideways}_{up}",
                               f"resolution {resolution}, placement {sideways}:{up}")
                hole = json.loads((out / "simulation.json").read_text())["hole_calibrations"][0]
                fluxes.append(hole["grid_flux_vs_dagan"])
                print(f"  resolution {resolution} (hole {HOLE * resolution / HEIGHT:.2f} cells), sideways {sideways:.2f}, "
                      f"up {up:.2f}: faces alone {hole['grid_flux_vs_dagan']:.4f} × Dagan, resistance "
                      f"{hole['resistance']:.4f}, calibrated {hole['calibrated_flux_vs_dagan']:.4f}", flush=True)
            means.append(statistics.mean(fluxes))
            print(f"resolution {resolution}: mean {means[-1]:.4f} × Dagan, spread {max(fluxes) / min(fluxes) - 1:+.1%}",
                  flush=True)
    if len(resolutions) >= 2:
        slope, limit = np.polyfit([1 / n for n in resolutions], means, 1)
        print(f"fitted in 1/resolution: {limit:.4f} × Dagan on an infinitely fine lattice "
              f"(slope {slope:.2f}); the engine's target is sim::kFreeJetFluxOverDagan")


if __name__ == "__main__":
    main()

#!/usr/bin/python3
r"""Steady Stokes flux through the sample cup's hole against grid size and where the hole sits.

The sample cup's bottom (hole radius 9 mm, 5 mm thick) spans a box 120 mm wide that is periodic along
z and full of liquid, and gravity drives the liquid through the hole. That isolates the hole from the
cup's free surfaces, so its flux can be compared across grids, placements and with Dagan, Weinbaum &
Pfeffer's (1982) orifice flux Q = ρ g L / (η (3/r³ + 8t/(π r⁴))), within about 1 % of the exact Stokes
flow in a wide box. The flux is the particles' mean vertical velocity times the liquid volume over the
period L. A placement "s:u" moves the cup s cells along x and y and u cells up, from the bottom's
underside on a row of z-faces; the sample cup at 48³ sits as "0:0.667" here at resolution 32 (the
same Δx), and at 96³ as "0:0.333" at resolution 64. Each placement runs with every hole conductance
of --conductances: "grid" (the faces as they are) and "dagan" (the default: the hole's drag, see
HoleCalibration in native/src/sim/sim.h, calibrated for a hole draining into a free jet, which passes
more than Dagan's flux, so here, with liquid on both sides, it need not match Dagan's).

    /usr/bin/python3 tests/bench/orifice_flux.py --resolutions 32 --placements 0:0.667,0.25:0.667,0.5:0.667
    /usr/bin/python3 tests/bench/orifice_flux.py --resolutions 32,64 --placements 0:0.25,0.5:0.25
"""
import argparse
import json
import math
import pathlib
import statistics
import sys
import tempfile

from viscosity_floor import read_particles, simulate  # beside this script

ROOT = pathlib.Path(__file__).resolve().parents[2]
WIDTH, PERIOD, BOTTOM_Z = 0.12, 0.06, 0.03  # m
HOLE, THICKNESS = 0.009, 0.005              # the sample cup's, m


def scene(resolution, sideways, up, conductance, viscosity, density, frames, seed):
    dx = WIDTH / resolution
    return {"format": "viscoscope.scene", "version": 1,
            "domain": {"min": [-WIDTH / 2, -WIDTH / 2, 0], "max": [WIDTH / 2, WIDTH / 2, PERIOD],
                       "resolution": resolution, "periodic": [False, False, True]},
            # Walls thicker than the box's half-diagonal: below the bottom the liquid fills the box.
            "solids": [{"type": "cup", "position": [sideways * dx, sideways * dx, BOTTOM_Z + up * dx],
                        "inner_radius": 0.043, "height": 3.0, "wall_thickness": 0.05,
                        "bottom_thickness": THICKNESS, "hole_radius": HOLE}],
            "liquids": [{"type": "box", "min": [-WIDTH / 2, -WIDTH / 2, 0], "max": [WIDTH / 2, WIDTH / 2, PERIOD]}],
            "material": {"density": density, "viscosity": viscosity, "surface_tension": 0.0},
            "gravity": [0, 0, -9.81], "fps": 30, "frames": frames, "seed": seed,
            "solver": {"hole_conductance": conductance},
            "output": {"particles": True, "vdb": False, "mesh": False}}


def parse_grids_and_placements(script, resolutions, placements):
    """--resolutions ("32,64") and --placements ("s:u,…") as lists; on a bad value exits with one line."""
    try:
        placements = [tuple(float(v) for v in p.split(":")) for p in placements.split(",")]
        resolutions = [int(r) for r in resolutions.split(",")]
    except ValueError as error:
        sys.exit(f"{script}: --placements takes s:u pairs and --resolutions integers ({error})")
    if any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in placements):
        sys.exit(f"{script}: every placement must be two finite numbers s:u")
    return resolutions, placements


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--engine", default=ROOT / "build/bin/viscoscope", type=pathlib.Path)
    parser.add_argument("--resolutions", default="32,64", help="cells across the 120 mm box")
    parser.add_argument("--placements", default="0:0.667,0.25:0.667,0.5:0.667",
                        help="comma-separated s:u, the cup moved s cells along x and y and u cells up")
    parser.add_argument("--conductances", default="grid,dagan", help="comma-separated: grid, dagan")
    parser.add_argument("--viscosity", type=float, default=100.0)
    parser.add_argument("--density", type=float, default=1400.0)
    parser.add_argument("--frames", type=int, default=3, help="frames simulated; the last one is read")
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    resolutions, placements = parse_grids_and_placements("orifice_flux", args.resolutions, args.placements)
    conductances = args.conductances.split(",")
    if not set(conductances) <= {"grid", "dagan"}:
        sys.exit(f"orifice_flux: --conductances takes grid and/or dagan, got {args.conductances}")
    if not (args.viscosity > 0 and args.density > 0 and args.frames > 0):
        sys.exit("orifice_flux: --viscosity, --density and --frames must be positive")

    dagan = args.density * 9.81 * PERIOD / (
        args.viscosity * (3 / HOLE ** 3 + 8 * THICKNESS / (math.pi * HOLE ** 4)))
    print(f"eta {args.viscosity} Pa·s, frame {args.frames}; Dagan's flux {dagan:.4g} m³/s")
    with tempfile.TemporaryDirectory(prefix="orifice_flux_") as tmp:
        for resolution in resolutions:
            for conductance in conductances:
                fluxes = []
                for sideways, up in placements:
                    out = simulate(args.engine,
                                   scene(resolution, sideways, up, conductance, args.viscosity, args.density,
                                         args.frames, args.seed),
                                   pathlib.Path(tmp) / f"{resolution}_{conductance}_{sideways}_{up}",
                                   f"{resolution}, {conductance}, placement {sideways}:{up}")
                    summary = json.loads((out / "simulation.json").read_text())
                    volume = summary["frames"][-1]["volume"]
                    w = read_particles(out / f"particles_{args.frames:05d}.bin")[:, 5]
                    flux = -float(w.mean()) * volume / PERIOD
                    fluxes.append(flux)
                    resistances = "".join(f", resistance {h['resistance']:.3f}" for h in summary["hole_calibrations"])
                    print(f"  resolution {resolution} (hole {HOLE * resolution / WIDTH:.2f} cells), {conductance}, "
                          f"sideways {sideways:.3f}, up {up:.3f}: flux {flux:.4g} m³/s, {flux / dagan:.3f} × Dagan"
                          f"{resistances}", flush=True)
                print(f"resolution {resolution}, {conductance}: median {statistics.median(fluxes) / dagan:.3f} × Dagan, "
                      f"spread {max(fluxes) / min(fluxes) - 1:+.1%}")


if __name__ == "__main__":
    main()

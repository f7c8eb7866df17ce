#!/usr/bin/python3
"""Diagnosis on measured data: the 1 % xanthan-gum solution of
../shared/data/measured/xanthan_constant_flux.csv, pumped up through an 8 mm hole in a horizontal
table at a constant flux and spreading radially for 746 s (Sayag & Worster 2013; see that folder's
README). No rheometry comes with it: what the liquid is made of is what the loop must find.

1. The scene: a ground plane, a disc emitter of the hole's radius at the centre pumping `--flux`
   kg/s (default PISM's 3.8173 g/s; the paper says "about 3 g/s") of a liquid of 1000 kg/m³,
   Newtonian, in a domain 0.6 m across at 1 mm cells.
2. The job: the measured radius alone (`track` with the observable "radius" from the hole's centre),
   simulated by the thin-film model (`"forward_model": "thin_film"`: minutes of spreading in a film
   about a centimetre thick, which the 3D solver cannot afford).
3. `viscoscope diagnose`: the Newtonian base and each candidate effect fitted to the first two
   thirds of the record and scored on the last third; it prints the conclusion, each model's
   parameters, E over the fitted and held-out frames, and the radius's error before and after.

    /usr/bin/python3 tests/bench/measured_xanthan.py [--flux 0.0038173] [--generations 30] [--work DIR]
"""
import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
DENSITY = 1000.0  # kg/m³, as PISM's set-up has it
HOLE_RADIUS = 0.008  # m


def scene(flux_kg_s, duration_s, interval_s):
    return {"format": "viscoscope.scene", "version": 1,
            "domain": {"min": [-0.3, -0.3, -0.01], "max": [0.3, 0.3, 0.05], "resolution": 600},
            "solids": [{"type": "ground", "height": 0.0}],
            "liquids": [{"type": "emitter", "center": [0, 0, 0], "normal": [0, 0, 1], "radius": HOLE_RADIUS,
                         "flux": flux_kg_s / DENSITY}],
            "material": {"density": DENSITY, "viscosity": 10.0, "surface_tension": 0.0},
            "fps": 1 / interval_s, "frames": int(round(duration_s / interval_s)) + 1}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared/data/measured/xanthan_constant_flux.csv"))
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--flux", type=float, default=3.8173e-3, help="kg/s pumped through the hole")
    parser.add_argument("--generations", type=int, default=30)
    parser.add_argument("--work", help="folder for the scene, job and results (default: a temporary one)")
    args = parser.parse_args()
    data = pathlib.Path(args.data).resolve()
    if not data.is_file():
        sys.exit(f"measured data not found: {data}")
    rows = [line.split(",") for line in data.read_text().splitlines()[1:] if line.strip()]
    times = [float(r[0]) for r in rows]
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="xanthan_"))
    work.mkdir(parents=True, exist_ok=True)
    (work / "scene.json").write_text(json.dumps(scene(args.flux, times[-1], times[1] - times[0]), indent=1))
    job = {"format": "viscoscope.job", "version": 1, "scene": "scene.json", "forward_model": "thin_film",
           "track": {"csv": str(data), "column": "radius_m", "observable": "radius", "origin": [0, 0, 0]},
           "parameters": [{"name": "viscosity", "initial": 10, "spread": 10, "min": 0.01, "max": 10000}],
           "max_generations": args.generations, "seed": 3}
    (work / "job.json").write_text(json.dumps(job, indent=1))
    started = time.monotonic()
    run = subprocess.run([args.engine, "diagnose", work / "job.json", "--out", work / "diagnosis", "--progress",
                          "none"], capture_output=True, text=True)
    seconds = time.monotonic() - started
    if run.returncode != 0:
        sys.exit(f"diagnose failed (exit {run.returncode}): {run.stderr.strip()}")
    report = json.loads((work / "diagnosis" / "diagnosis.json").read_text())
    print(f"data {data.name}: {len(rows)} radii over {times[-1]:.0f} s; flux {args.flux * 1e3:.4g} g/s; "
          f"diagnose {seconds:.1f} s wall; work {work}")
    print(json.dumps({k: report[k] for k in report if k not in ("candidates", "base")}, indent=1)[:3000])
    for model in [report["base"]] + report["candidates"]:
        print(json.dumps(model)[:1500])


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""The loop on real non-Newtonian liquids: the dam breaks of ../shared/data/measured/virheometry/, a
thickened Worcestershire sauce and a lotion, each released from two reservoirs of different shape and
measured independently on a rheometer (data of Hamamichi, Nagasawa, Okada, Seto & Yue, "Non-Newtonian
ViRheometry via Similarity Analysis", ACM TOG 42(6):193, 2023, CC BY-NC 4.0; see that folder's README).

For each liquid:
1. Two scenes, one per reservoir: the reservoir W long (x from the back wall at 0 to the gate at W),
   4 cm deep across, filled level to H, side walls along the reservoir only, an open plate beyond
   the gate and no gate (it is gone at t = 0); ρ from the README, Newtonian, no surface tension
   (not measured). The domain reaches past the last measured front and sideways for the lobe.
2. One job with both runs (`runs`), each compared on its measured front from the gate plane along
   +x within ±1 cm of the centre line (`track`, observable "front"), η searched; the rheometer's
   Herschel–Bulkley fit over 0.1–100 s⁻¹ (the README's table, `--temperature`) as the job's
   `rheometer` curve.
3. `viscoscope diagnose` with every candidate (or `--effects`) on `--threads` threads within
   `--time-budget` seconds: the conclusion, each run's own Newtonian η, each model's parameters and
   held-out E, and the chosen law's flow curve against the rheometer's over the shear rates the
   simulation exercised (log10 of stress, RMS: ViRheometry's own are 0.05–0.14).
   Or, with `--power-law`, `viscoscope identify` of a power law's K and n on both runs' every frame
   (from K 2.5 Pa·sⁿ, n 0.75), to the end of `--generations` or `--time-budget`: its K and n with
   their intervals, why it stopped, and its flow curve against the rheometer's over `--rates` (else
   the range a diagnosis in the same `--work` folder measured for its power law, else 1–100 s⁻¹).

    /usr/bin/python3 tests/bench/virheometry.py [--liquid sauce|lotion|both] [--resolution 48]
        [--time-budget 1800] [--threads 2] [--effects a,b] [--power-law [--rates LOW HIGH]] [--work DIR]
"""
import argparse
import json
import math
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared/data/measured/virheometry"
RESERVOIR_DEPTH = 0.04  # m across, the side walls' distance
CENTRE_BAND = 0.01  # m either side of the centre line where the front is measured
# Each liquid: its density (kg/m³), its runs (the CSV, fill height H and reservoir length W in m)
# and the rheometer's Herschel–Bulkley fit over 0.1–100 s⁻¹ per temperature (τ_y Pa, K Pa·sⁿ, n).
LIQUIDS = {
    "sauce": {"density": 1200,
              "runs": [("dambreak_JapaneseThickenedWorcestershireSauce_4.0_2.1_1.csv", 0.040, 0.021),
                       ("dambreak_JapaneseThickenedWorcestershireSauce_2.0_3.0_2.csv", 0.020, 0.030)],
              "rheometer": {22: (0.73, 1.96, 0.503), 23: (0.79, 1.85, 0.512), 24: (0.69, 1.97, 0.502),
                            25: (0.63, 1.75, 0.505)}},
    "lotion": {"density": 1000,
               "runs": [("dambreak_Lotion_7.0_7.0_2.csv", 0.070, 0.070),
                        ("dambreak_Lotion_2.5_5.1_1.csv", 0.025, 0.051)],
               "rheometer": {22: (4.15, 7.29, 0.466), 23: (4.12, 7.49, 0.461), 24: (4.06, 7.21, 0.469),
                             25: (3.99, 7.13, 0.467)}},
}


def read_front(csv):
    rows = [line.split(",") for line in csv.read_text().splitlines()[1:] if line.strip()]
    return [(float(r[0]), float(r[1])) for r in rows]


def scene(density, height, length, last_front, resolution):
    """The reservoir at the back of a plate that reaches 30 % past the last measured front, as wide
    as the lobe may spread (the front's reach either side of the reservoir), 20 % above the fill."""
    reach = 1.3 * last_front
    half_width = RESERVOIR_DEPTH / 2 + 0.6 * last_front
    top = 1.2 * height
    extent = max(length + reach, 2 * half_width, top)
    wall = 2 * extent / resolution  # two cells thick
    side = lambda y0, y1: {"type": "box", "min": [0, y0, 0], "max": [length, y1, top]}
    half = RESERVOIR_DEPTH / 2
    return {"format": "viscoscope.scene", "version": 1,
            "domain": {"min": [0, -half_width, 0], "max": [length + reach, half_width, top], "resolution": resolution},
            "solids": [side(half, half + wall), side(-half - wall, -half)],
            "liquids": [{"type": "box", "min": [0, -half, 0], "max": [length, half, height]}],
            "material": {"density": density, "viscosity": 2.0, "surface_tension": 0.0},
            "gravity": [0, 0, -9.81], "fps": 24, "frames": 8, "seed": 3}


def rheometer_csv(path, yield_stress, consistency, index):
    """The rheometer's fitted curve at its ramp's 21 shear rates, 0.1 to 1000 s⁻¹ (within the fit's
    0.1–100 s⁻¹ the fit is within 1–2 % of the points)."""
    rates = [10 ** (-1 + 4 * k / 20) for k in range(21)]
    lines = ["shear_rate_per_s,stress_pa"] + [f"{g:.6g},{yield_stress + consistency * g ** index:.6g}" for g in rates
                                              if g <= 100]
    path.write_text("\n".join(lines) + "\n")


def run_liquid(args, name):
    liquid = LIQUIDS[name]
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="virheometry_")) / name
    work.mkdir(parents=True, exist_ok=True)
    runs = []
    for k, (csv, height, length) in enumerate(liquid["runs"]):
        data = DATA / csv
        if not data.is_file():
            sys.exit(f"measured data not found: {data}")
        front = read_front(data)
        (work / f"scene{k}.json").write_text(
            json.dumps(scene(liquid["density"], height, length, front[-1][1], args.resolution), indent=1))
        runs.append({"scene": f"scene{k}.json",
                     "track": {"csv": str(data), "column": "front_m", "observable": "front",
                               "origin": [length, 0, 0], "direction": [1, 0, 0], "band": CENTRE_BAND}})
    rheometer_csv(work / "rheometer.csv", *liquid["rheometer"][args.temperature])
    job = {"format": "viscoscope.job", "version": 1, "runs": runs, "rheometer": "rheometer.csv",
           "parameters": [{"name": "viscosity", "initial": 2, "spread": 2, "min": 0.05, "max": 200}],
           "resolution": args.resolution, "max_generations": args.generations, "seed": 5}
    (work / "job.json").write_text(json.dumps(job, indent=1))
    if args.power_law:
        identify_power_law(args, name, work, job)
        return
    command = [args.engine, "diagnose", work / "job.json", "--out", work / "diagnose", "--progress", "text",
               "--threads", str(args.threads), "--time-budget", str(args.time_budget)]
    if args.effects:
        command += ["--effects", args.effects]
    started = time.monotonic()
    run = subprocess.run(command, capture_output=True, text=True)
    wall = time.monotonic() - started
    if run.returncode != 0:
        sys.exit(f"diagnose failed (exit {run.returncode}): {run.stderr.strip()}")
    report(name, json.loads((work / "diagnose/diagnosis.json").read_text()), wall, args)


def identify_power_law(args, name, work, job):
    """K and n of a power law searched together on both runs, each run's scene turned into that law."""
    for run in job["runs"]:
        scene_file = work / f"power_law_{run['scene']}"
        doc = json.loads((work / run["scene"]).read_text())
        doc["material"]["model"] = {"type": "power_law", "consistency": 2.5, "flow_index": 0.75}
        scene_file.write_text(json.dumps(doc, indent=1))
        run["scene"] = scene_file.name
    job["parameters"] = [{"name": "consistency", "initial": 2.5, "spread": 1.0, "min": 0.05, "max": 200},
                         {"name": "flow_index", "initial": 0.75, "spread": 0.3, "min": 0.1, "max": 1.0}]
    job["time_budget_s"] = args.time_budget
    (work / "power_law_job.json").write_text(json.dumps(job, indent=1))
    command = [args.engine, "identify", work / "power_law_job.json", "--out", work / "power_law", "--progress",
               "none", "--threads", str(args.threads), "--no-fields", "--no-plots"]
    started = time.monotonic()
    run = subprocess.run(command, capture_output=True, text=True)
    wall = time.monotonic() - started
    if run.returncode != 0:
        sys.exit(f"identify failed (exit {run.returncode}): {run.stderr.strip()}")
    result = json.loads((work / "power_law/result.json").read_text())
    K, n = (result["parameters"][p]["value"] for p in ("consistency", "flow_index"))
    print(f"{name}: power law on both runs, {args.resolution} cells, {args.threads} threads, {wall:.0f} s wall: "
          f"{values(result)} ({result['parameters']['flow_index']['interval_method'].split(':')[0]}); "
          f"E {result['E']:.4g}, {result['generations']} generations ({result['coarse_generations']} coarse), "
          f"{result['evaluations']} evaluations, stopped {result['stop']}")
    rates = args.rates
    diagnosis = work / "diagnose/diagnosis.json"
    if not rates and diagnosis.is_file():
        fits = [m for m in json.loads(diagnosis.read_text())["candidates"] if m["model"] == "shear_thinning"]
        rates = fits[0].get("shear_rate_range_per_s") if fits else None
    low, high = rates or (1, 100)
    tau_y, k_rheometer, n_rheometer = LIQUIDS[name]["rheometer"][args.temperature]
    steps = [low * (high / low) ** (k / 15) for k in range(16)]
    rms = math.sqrt(sum(math.log10(K * g ** n / (tau_y + k_rheometer * g ** n_rheometer)) ** 2 for g in steps) / 16)
    print(f"  flow curve: log10 stress RMS {rms:.3f} against the rheometer ({args.temperature} °C) over "
          f"{low:.3g}–{high:.3g} s⁻¹")
    for line in result["doubts"]:
        print(f"  doubt: {line}")


def values(model):
    return ", ".join(f"{n} = {p['value']:.4g} [{p['interval'][0]:.4g}, {p['interval'][1]:.4g}]"
                     for n, p in model["parameters"].items())


def report(name, d, wall, args):
    print(f"{name}: {args.resolution} cells, {args.threads} threads, budget {args.time_budget:.0f} s, "
          f"{wall:.0f} s wall; fitted frames {d['fitted_frames']}")
    print(f"  conclusion: {d['conclusion']}")
    for entry in d.get("base_per_run", []):
        print(f"  run {entry['run']} alone: {values(entry)}, front error {100 * entry.get('track_error', math.nan):.1f} %")
    for model in [d["base"]] + d["candidates"]:
        print(f"  {model['model']}: {values(model)}; held-out E {model['held_out_E']:.4g}, BIC {model['bic']:.1f}, "
              f"{model['evaluations']} evaluations, {model['seconds']:.0f} s, stopped {model.get('stopped')}")
    for tried in d["not_tried"]:
        print(f"  not tried: {tried['effect']}: {tried['why']}")
    curve = d.get("flow_curve")
    if curve:
        low, high = curve["shear_rate_range_per_s"]
        line = f"  flow curve of {curve['model']} over {low:.3g}–{high:.3g} s⁻¹"
        rms = curve.get("rheometer", {}).get("log_stress_rms")
        if rms is not None:
            over = curve["rheometer"]["shear_rate_range_per_s"]
            line += (f": log10 stress RMS {rms:.3f} against the rheometer ({args.temperature} °C) over "
                     f"{over[0]:.3g}–{over[1]:.3g} s⁻¹")
        print(line)
    for warning in d["warnings"]:
        print(f"  warning: {warning}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--liquid", choices=("sauce", "lotion", "both"), default="both")
    parser.add_argument("--engine", default=str(ROOT / "build/bin/viscoscope"))
    parser.add_argument("--resolution", type=int, default=48, help="cells along each domain's longest axis")
    parser.add_argument("--generations", type=int, default=30)
    parser.add_argument("--time-budget", type=float, default=1800, help="wall seconds per liquid")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--temperature", type=int, choices=(22, 23, 24, 25), default=23,
                        help="°C of the rheometer's ramp compared with")
    parser.add_argument("--effects", help="the candidates, comma-separated (default: every one)")
    parser.add_argument("--power-law", action="store_true",
                        help="identify a power law's K and n on both runs instead of diagnosing")
    parser.add_argument("--rates", type=float, nargs=2, metavar=("LOW", "HIGH"),
                        help="with --power-law: the shear rates (1/s) its flow curve is compared over")
    parser.add_argument("--work", help="folder for the scenes, jobs and results (default: a temporary one)")
    args = parser.parse_args()
    for name in (("sauce", "lotion") if args.liquid == "both" else (args.liquid,)):
        run_liquid(args, name)


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Plots of a diagnosis: OUT/diagnosis.png from OUT/diagnosis.json.

Top, per run: the residual over time of the base fit and of the chosen effect (the measured track
against each simulation, or each frame's silhouette E), the fitted frames left of the dashed line
and the predicted ones right of it. Then every model's E over the fitted and the held-out frames,
and beside it the answer's flow curve τ(γ̇) over the shear rates its flow exercised, with its band
and the job's rheometer curve when it names one. Bottom: the landscape of the chosen effect's new
parameters (the base's, when none is chosen): E over the fitted frames at every evaluation of its
fit (OUT/fits/<model>/evaluations.csv), θ* marked.

Usage: /usr/bin/python3 scripts/plot_diagnosis.py OUT
Needs matplotlib (Debian: python3-matplotlib). `viscoscope diagnose` calls this script itself.
"""
import csv
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def series_lines(ax, series, label, style):
    times = [p["time_s"] for p in series]
    if any("measured" in p for p in series):
        points = [p for p in series if "measured" in p]
        ax.plot([p["time_s"] for p in points], [p["simulated"] - p["measured"] for p in points], style, label=label)
        ax.set_ylabel("simulated − measured (m)")
    else:
        ax.plot(times, [p.get("frame_E", 0.0) for p in series], style, label=label)
        ax.set_ylabel("silhouette E per frame")


def landscape(ax, evaluations, name, best):
    """E against one parameter over a fit's evaluations, log-log, the fit's value marked."""
    points = [(float(e[name]), float(e["E"])) for e in evaluations if e.get(name) and e.get("E")]
    ax.plot([p[0] for p in points], [p[1] for p in points], "o", alpha=0.5)
    ax.axvline(best, color="tab:red", linestyle="--", label="fit %.4g" % best)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(name)
    ax.set_ylabel("E (fitted frames)")
    ax.legend()


def flow_curve(ax, curve):
    """The answer's stress against shear rate, log-log, its band shaded, the rheometer's points."""
    points = curve["points"]
    rates = [p["shear_rate_per_s"] for p in points]
    ax.plot(rates, [p["stress_pa"] for p in points], "-", color="C0", label=curve["model"])
    if all("stress_band_pa" in p for p in points):
        ax.fill_between(rates, [p["stress_band_pa"][0] for p in points], [p["stress_band_pa"][1] for p in points],
                        color="C0", alpha=0.25, label="band of the intervals")
    rheometer = curve.get("rheometer")
    if rheometer:
        rms = rheometer.get("log_stress_rms")
        label = "rheometer" + (" (log RMS %.2f)" % rms if rms is not None else "")
        ax.plot([p[0] for p in rheometer["points"]], [p[1] for p in rheometer["points"]], "k.", label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("shear rate (1/s)")
    ax.set_ylabel("stress (Pa)")
    ax.set_title("flow curve (line: the shear rates exercised)", fontsize=10)
    ax.legend(fontsize=8)


def main(out_dir):
    with open(os.path.join(out_dir, "diagnosis.json"), encoding="utf-8") as fh:
        diagnosis = json.load(fh)
    base = diagnosis["base"]
    chosen = next((c for c in diagnosis["candidates"] if c["model"] == diagnosis["chosen"]), None)
    runs = len(base["residual_over_time"])
    verdict = {"missing_effect": "missing effect: %s" % (chosen or {}).get("title", diagnosis["chosen"]),
               "no_missing_effect": "no missing effect", "cannot_tell": "cannot tell"}[diagnosis["verdict"]]
    shown = chosen or base
    new = [n for n in shown["parameters"] if chosen is None or n not in base["parameters"]]
    path = os.path.join(out_dir, shown["folder"], "evaluations.csv")
    evaluations = []
    if new and os.path.isfile(path):
        with open(path, encoding="utf-8", newline="") as fh:
            evaluations = list(csv.DictReader(fh))
    curve = diagnosis.get("flow_curve")
    columns = max(2 if curve else 1, len(new))
    fig = plt.figure(figsize=(11 if curve else 7, 3 * (runs + 1 + bool(evaluations))))
    grid = fig.add_gridspec(runs + 1 + bool(evaluations), columns)
    for r in range(runs):
        ax = fig.add_subplot(grid[r, :])
        series_lines(ax, base["residual_over_time"][r], "base (before)", "o-")
        if chosen:
            series_lines(ax, chosen["residual_over_time"][r], chosen["model"] + " (after)", "s-")
        fitted = [p["time_s"] for p in base["residual_over_time"][r] if p["fitted"]]
        if fitted:
            ax.axvline(max(fitted), color="gray", linestyle="--")
        ax.axhline(0, color="black", linewidth=0.5)
        ax.set_xlabel("time (s)")
        ax.set_title(f"run {r + 1}: {verdict}")
        ax.legend()
    ax = fig.add_subplot(grid[runs, :columns - 1] if curve else grid[runs, :])
    models = [base] + diagnosis["candidates"]
    x = range(len(models))
    ax.bar([i - 0.2 for i in x], [m["fitted_E"] for m in models], width=0.4, label="fitted frames")
    ax.bar([i + 0.2 for i in x], [m["held_out_E"] for m in models], width=0.4, label="held-out frames")
    visible = diagnosis["noise_floor"]["visible_share"]
    if 0 < visible < 1:
        ax.axhline(base["held_out_E"] * (1 - visible), color="C1", linestyle=":",
                   label="held-out E a named effect must beat (noise floor)")
    ax.set_xticks(list(x))
    ax.set_xticklabels([m["model"] for m in models], rotation=20, fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("E")
    ax.legend(fontsize=8)
    if curve:
        flow_curve(fig.add_subplot(grid[runs, columns - 1]), curve)
    for k, name in enumerate(new if evaluations else []):
        ax = fig.add_subplot(grid[runs + 1, k])
        landscape(ax, evaluations, name, shown["parameters"][name]["value"])
        ax.set_title(f"{shown['model']}: {name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "diagnosis.png"), dpi=100)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])

#!/usr/bin/python3
"""Plots of a diagnosis: OUT/diagnosis.png from OUT/diagnosis.json.

Top, per run: the residual over time of the base fit and of the chosen effect (the measured track
against each simulation, or each frame's silhouette E), the fitted frames left of the dashed line
and the predicted ones right of it. Bottom: every model's E over the fitted and the held-out frames.

Usage: /usr/bin/python3 scripts/plot_diagnosis.py OUT
Needs matplotlib (Debian: python3-matplotlib). `viscoscope diagnose` calls this script itself.
"""
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


def main(out_dir):
    with open(os.path.join(out_dir, "diagnosis.json"), encoding="utf-8") as fh:
        diagnosis = json.load(fh)
    base = diagnosis["base"]
    chosen = next((c for c in diagnosis["candidates"] if c["model"] == diagnosis["chosen"]), None)
    runs = len(base["residual_over_time"])
    fig, axes = plt.subplots(runs + 1, 1, figsize=(7, 3 * (runs + 1)))
    for r in range(runs):
        ax = axes[r]
        series_lines(ax, base["residual_over_time"][r], "base (before)", "o-")
        if chosen:
            series_lines(ax, chosen["residual_over_time"][r], chosen["model"] + " (after)", "s-")
        fitted = [p["time_s"] for p in base["residual_over_time"][r] if p["fitted"]]
        if fitted:
            ax.axvline(max(fitted), color="gray", linestyle="--")
        ax.axhline(0, color="black", linewidth=0.5)
        ax.set_xlabel("time (s)")
        ax.set_title(f"run {r + 1}: {diagnosis['conclusion']}")
        ax.legend()
    ax = axes[-1]
    models = [base] + diagnosis["candidates"]
    x = range(len(models))
    ax.bar([i - 0.2 for i in x], [m["fitted_E"] for m in models], width=0.4, label="fitted frames")
    ax.bar([i + 0.2 for i in x], [m["held_out_E"] for m in models], width=0.4, label="held-out frames")
    ax.set_xticks(list(x))
    ax.set_xticklabels([m["model"] for m in models])
    ax.set_yscale("log")
    ax.set_ylabel("E")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "diagnosis.png"), dpi=100)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])

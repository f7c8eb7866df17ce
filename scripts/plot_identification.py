#!/usr/bin/python3
"""Plots of an identification: OUT/convergence.png and OUT/landscape.png from OUT/result.json.

Usage: /usr/bin/python3 scripts/plot_identification.py OUT
Needs matplotlib (Debian: python3-matplotlib). `viscoscope identify` calls this script itself.
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(out_dir):
    with open(os.path.join(out_dir, "result.json"), encoding="utf-8") as fh:
        result = json.load(fh)
    history = result["history"]
    evaluated = result["evaluated"]
    names = list(result["parameters"].keys())
    name = names[0]
    unit = {"viscosity": "η (Pa·s)", "surface_tension": "σ (N/m)"}.get(name, name)
    coarse_end = result.get("coarse_generations", 0)

    # Convergence: E per generation (best so far at that fidelity, and the generation's best) and θ.
    fig, (ax_e, ax_t) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    gens = [h["generation"] for h in history]
    best = [h["best_E"] if h["best_E"] is not None else math.nan for h in history]
    gen_best = [h["generation_best_E"] if h["generation_best_E"] is not None else math.nan for h in history]
    ax_e.semilogy(gens, gen_best, "o", ms=4, color="0.6", label="best of generation")
    ax_e.semilogy(gens, best, "-", color="C0", label="best so far (per fidelity)")
    ax_e.set_ylabel("E")
    ax_e.legend(loc="upper right", fontsize=8)
    ax_e.set_title("Identification: %d generations, %d evaluations, stop: %s"
                   % (result["generations"], result["evaluations"], result["stop"]))
    mean = [h["mean_theta"][0] for h in history]
    best_t = [h["best_theta"][0] if h["best_theta"] is not None else math.nan for h in history]
    sd = [h["log_std"][0] for h in history]
    ax_t.semilogy(gens, mean, "-", color="C1", label="CMA-ES mean")
    ax_t.fill_between(gens, [m * math.exp(-2 * s) for m, s in zip(mean, sd)],
                      [m * math.exp(2 * s) for m, s in zip(mean, sd)], color="C1", alpha=0.2,
                      label="mean · exp(±2σ√C)")
    ax_t.semilogy(gens, best_t, "o-", ms=3, color="C0", label="best evaluated")
    ax_t.set_ylabel(unit)
    ax_t.set_xlabel("generation")
    for ax in (ax_e, ax_t):
        if 0 < coarse_end < len(history):
            ax.axvspan(0.5, coarse_end + 0.5, color="0.9", zorder=0)
    if 0 < coarse_end:
        ax_t.text(1, ax_t.get_ylim()[1], " coarse: %d³, frames 0..%d" % (result["coarse_resolution"],
                                                                         result["coarse_frames"]),
                  va="top", fontsize=8)
    ax_t.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "convergence.png"), dpi=110)
    plt.close(fig)

    # Landscape: every evaluation E(θ), per fidelity, with θ* and its interval.
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, fidelity in enumerate(("coarse", "full")):
        runs = [e for e in evaluated if e["fidelity"] == fidelity and e["E"] is not None]
        pts = sorted((e["theta"][0], e["E"]) for e in runs)
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o", ms=4, alpha=0.75, color="C%d" % i,
                    label="%s: %d³, frames 0..%d" % (fidelity, runs[0]["resolution"], runs[0]["frames"]))
    # The parabolic proposals the full-fidelity generations injected (see identification.cpp).
    proposals = [(e["theta"][0], e["E"]) for e in evaluated if e.get("origin") == "parabola" and e["E"] is not None]
    if proposals:
        ax.plot([p[0] for p in proposals], [p[1] for p in proposals], "o", ms=8, mfc="none", color="C3",
                label="parabolic proposals (%d)" % len(proposals))
    param = result["parameters"][name]
    lo, hi = param["interval"]
    ax.axvspan(lo, hi, color="C2", alpha=0.15, label="interval (%s)" % param["interval_method"].split(":")[0])
    ax.axvline(param["value"], color="C2", label="θ* = %.4g" % param["value"])
    fit = param.get("profile_fit", {})
    if "coefficients" in fit and "theta_min" in fit:
        # The parabola θ* comes from, over the evaluations it was fitted to (within e^±0.5 of the best).
        a, b, c = fit["coefficients"]
        inverse = fit.get("variable") == "1/θ"
        to_u = (lambda t: 1.0 / t) if inverse else math.log
        best_theta = param["best_evaluation"]
        thetas = [best_theta * math.exp(-0.5 + i / 100.0) for i in range(101)]
        curve = [a + b * (to_u(t) - to_u(best_theta)) + c * (to_u(t) - to_u(best_theta)) ** 2 for t in thetas]
        ax.plot(thetas, curve, "-", color="C2", alpha=0.6, label="parabola in %s" % fit.get("variable", "ln θ"))
    ax.set_xscale("log")
    ax.set_xlabel(unit)
    ax.set_ylabel(r"$E = \sum_f \omega_f E_f$")
    values = [e["E"] for e in evaluated if e["E"] is not None and e["E"] > 0]
    if values and max(values) > 5 * min(values):
        ax.set_yscale("log")
    ax.set_title("Objective landscape (every evaluated θ)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "landscape.png"), dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])

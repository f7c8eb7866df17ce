#!/usr/bin/python3
"""Diagnose on the capture scene from the Blender panel, within its time budget (issue 89: on this
Newtonian clip never a named effect, and the real time within 10 % of the budget).

1. `sample_scenes/capture_scene.py --clip` builds the scene and its clip (the engine's pour of honey,
   η = 8 Pa·s, rendered by Cycles), as `tests/blender/test_capture_identify.py` does; `--reuse`
   keeps a WORK/capture.blend made before.
2. For each budget and thread count: Blender opens the scene, sets the add-on's engine threads and
   the Diagnose panel's Time Budget, and presses Diagnose (the panel's job, every effect ticked).
3. Prints the wall time against the budget, the verdict and the conclusion, each fit's evaluations
   and seconds, the effects not tried and why, and the buttons the panel offers.

    /usr/bin/python3 tests/bench/capture_diagnosis.py [--minutes 8 15 30] [--threads 1 2] [--work DIR] [--reuse]
"""
import argparse
import json
import pathlib
import subprocess
import sys
import textwrap
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]

DIAGNOSE_SCRIPT = textwrap.dedent('''
    import json, os, sys
    import bpy
    root, work, minutes, threads = sys.argv[sys.argv.index("--") + 1:]
    sys.path.insert(0, os.path.join(root, "sample_scenes"))
    import _common
    _common.enable_addon()
    from viscoscope import prefs
    from viscoscope.operators.diagnose import diagnose_dir, suggestions
    prefs.get().threads = int(threads)
    scene = bpy.context.scene
    vs = scene.viscoscope
    vs.work_dir = work
    vs.diagnosis_budget_minutes = float(minutes)
    done = bpy.ops.viscoscope.diagnose('EXEC_DEFAULT')
    with open(os.path.join(work, "summary.json"), "w") as fh:
        json.dump({"diagnose": sorted(done), "error": vs.diagnose_job.error, "verdict": vs.diagnosis_verdict,
                   "grid": vs.diagnosis_grid, "buttons": [text for _s, _v, text in suggestions(vs)],
                   "out": os.path.join(diagnose_dir(scene), "out")}, fh)
''')


def blender(*args):
    done = subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", *map(str, args)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"blender failed (exit {done.returncode}): {(done.stdout + done.stderr)[-2000:]}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[8.0], help="the Diagnose panel's Time Budget")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="the add-on's engine threads")
    parser.add_argument("--work", default=str(ROOT / "out/capture_diagnosis"), help="folder for the scene and runs")
    parser.add_argument("--reuse", action="store_true", help="keep WORK/capture.blend and its clip")
    args = parser.parse_args()
    work = pathlib.Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    if not (args.reuse and (work / "capture.blend").is_file()):
        blender("--python", ROOT / "sample_scenes/capture_scene.py", "--", "--out", work, "--clip", "--samples", "4")
    script = work / "diagnose_capture.py"
    script.write_text(DIAGNOSE_SCRIPT)
    for minutes in args.minutes:
        for threads in args.threads:
            run = work / f"run_{minutes:g}min_{threads}threads"
            started = time.monotonic()
            blender(work / "capture.blend", "--python", script, "--", ROOT, run, minutes, threads)
            seconds = time.monotonic() - started
            summary = json.loads((run / "summary.json").read_text())
            if summary["diagnose"] != ["FINISHED"]:
                print(f"{minutes:g} min, {threads} thread(s): Diagnose {summary['diagnose']}: {summary['error']}")
                continue
            report = json.loads((pathlib.Path(summary["out"]) / "diagnosis.json").read_text())
            budget = 60 * minutes
            print(f"{minutes:g} min, {threads} thread(s): {seconds:.0f} s in Blender against {budget:.0f} s "
                  f"({seconds / budget:.2f}×; the engine's fits and scorings {report['seconds']:.0f} s); "
                  f"{summary['grid']}; {report['verdict']}: {report['conclusion']}")
            for fit in [report["base"]] + report["candidates"]:
                values = ", ".join(f"{name} {p['value']:.4g}" for name, p in fit["parameters"].items())
                print(f"  {fit['model']:15s} {values}; {fit['evaluations']} evaluations, search {fit['seconds']:.0f} s "
                      f"(share {fit['time_budget_s']:.0f}), scoring {fit['scoring_seconds']:.0f} s, "
                      f"held-out E {fit['held_out_E']:.4g}" + (f", stopped: {fit['stopped']}" if "stopped" in fit else ""))
            for skipped in report["not_tried"]:
                print(f"  not tried: {skipped['effect']} ({skipped['why']})")
            for button in summary["buttons"]:
                print(f"  panel offers: {button}")


if __name__ == "__main__":
    main()

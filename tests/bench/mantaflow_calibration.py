#!/usr/bin/python3
"""Benchmark: Mantaflow's viscosity_value calibrated against the capture cup's footage, against the
formula's ν·0.4 s/L² (issue 65 §3). Prints figures; never asserts on time.

    /usr/bin/python3 tests/bench/mantaflow_calibration.py [--etas 20,3] [--res 64] [--workdir DIR]

For each η it builds the capture scene with a reference clip rendered from the engine's own
simulation at η (sample_scenes/capture_scene.py --clip --eta η --mantaflow RES: Cycles, --frames),
extracts the clip's silhouettes with the Silhouettes panel's settings (Preview Silhouettes), and runs
Calibrate Mantaflow to Footage on the Mantaflow domain the scene builder adds over the same cup (the
formula's value from that η, ρ = 1400 kg/m³). It prints the formula's viscosity_value, the calibrated
one, their ratio, E at every value baked, the bake resolution and the wall times.

Run inside Blender with --stage calibrate, this file is the second step for one built scene.
"""

import argparse
import json
import os
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RESULT_TAG = "CALIBRATION_RESULT "


def stage_calibrate():
    """Inside Blender, on DIR/capture.blend: Preview Silhouettes, then Calibrate Mantaflow."""
    import bpy
    sys.path.insert(0, os.path.join(REPO, "sample_scenes"))
    import _common
    _common.enable_addon()
    scene = bpy.context.scene
    vs = scene.viscoscope
    t0 = time.perf_counter()
    if bpy.ops.viscoscope.preview_silhouettes('EXEC_DEFAULT') != {'FINISHED'}:
        raise SystemExit("error: extraction failed: %s" % vs.extract_job.error)
    extract_s = time.perf_counter() - t0
    domain = bpy.data.objects["Mantaflow Domain"]
    bpy.context.view_layer.objects.active = domain
    t0 = time.perf_counter()
    result = bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT')
    calibrate_s = time.perf_counter() - t0
    if result != {'FINISHED'}:
        raise SystemExit("error: calibration failed: %s" % vs.calibrate_job.error)
    from viscoscope.operators.mantaflow_calibration import calibration_dir
    with open(os.path.join(calibration_dir(scene), "out", "calibration.json"), encoding="utf-8") as fh:
        doc = json.load(fh)
    doc.update(extract_seconds=extract_s, calibrate_seconds=calibrate_s, eta=vs.fluid.viscosity,
               density=vs.fluid.density, blender=bpy.app.version_string)
    print(RESULT_TAG + json.dumps(doc), flush=True)


def run(cmd, log_path):
    t0 = time.perf_counter()
    with open(log_path, "wb") as log:
        code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=REPO)
    return code, time.perf_counter() - t0


def tail(path, lines=8):
    with open(path, errors="replace") as fh:
        return "".join(fh.readlines()[-lines:])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--etas", default="20,3", help="comma-separated η of the reference clips, Pa·s")
    p.add_argument("--res", type=int, default=64, help="Mantaflow resolution_max of the calibration bakes")
    p.add_argument("--frames", type=int, default=24, help="frames of the reference clip (30 fps)")
    p.add_argument("--samples", type=int, default=4, help="Cycles samples of the reference clip")
    p.add_argument("--workdir", default=os.path.join(REPO, "build", "bench", "mantaflow_calibration"))
    p.add_argument("--blender", default="/usr/bin/blender")
    p.add_argument("--engine", default=os.path.join(REPO, "build", "bin", "viscoscope"))
    p.add_argument("--json", help="write the records here (default: WORKDIR/results.json)")
    args = p.parse_args()
    env = dict(os.environ, VISCOSCOPE_ENGINE=args.engine)
    os.environ.update(VISCOSCOPE_ENGINE=args.engine)
    records = []
    for eta in [float(x) for x in args.etas.split(",") if x.strip()]:
        out = os.path.join(args.workdir, "eta%g" % eta)
        os.makedirs(out, exist_ok=True)
        blend = os.path.join(out, "capture.blend")
        build_s = None
        if not os.path.isfile(blend):  # the clip takes minutes: a rerun keeps it
            code, build_s = run([args.blender, "-b", "--factory-startup", "--python",
                                 os.path.join(REPO, "sample_scenes", "capture_scene.py"), "--", "--out", out,
                                 "--clip", "--eta", str(eta), "--mantaflow", str(args.res), "--frames", str(args.frames),
                                 "--samples", str(args.samples)], os.path.join(out, "build.log"))
            if code != 0:
                sys.exit("η %g: building the scene failed:\n%s" % (eta, tail(os.path.join(out, "build.log"))))
        log = os.path.join(out, "calibrate.log")
        cmd = [args.blender, "-b", "--factory-startup", blend, "--python-exit-code", "1", "--python",
               os.path.abspath(__file__), "--", "--stage", "calibrate"]
        t0 = time.perf_counter()
        with open(log, "wb") as fh:
            code = subprocess.call(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=REPO, env=env)
        wall = time.perf_counter() - t0
        doc = None
        with open(log, errors="replace") as fh:
            for line in fh:
                if line.startswith(RESULT_TAG):
                    doc = json.loads(line[len(RESULT_TAG):])
        if code != 0 or doc is None:
            sys.exit("η %g: calibration failed:\n%s" % (eta, tail(log)))
        doc.update(build_seconds=build_s, wall_seconds=wall)
        records.append(doc)
        print_record(doc)
    path = args.json or os.path.join(args.workdir, "results.json")
    with open(path, "w") as fh:
        json.dump(records, fh, indent=1)
    print("JSON: %s" % path)


def print_record(doc):
    print("η %g Pa·s (ρ %g): resolution %d, %d frames; formula viscosity_value %.4g, calibrated %.4g, "
          "ratio %.3g%s" % (doc["eta"], doc["density"], doc["resolution"], doc["frames"], doc["formula_value"],
                            doc["chosen_value"], doc["ratio"], "" if doc["bracketed"] else " (NOT bracketed)"))
    for v in doc["values"]:
        print("  viscosity_value %.4g (%.3g × formula): E %.4f, bake %.1f s%s"
              % (v["viscosity_value"], v["viscosity_value"] / doc["formula_value"], v["E"], v["bake_seconds"],
                 "  ← chosen" if v["viscosity_value"] == doc["chosen_value"] else ""))
    build = doc.get("build_seconds")
    print("  wall: scene and clip %s, extraction %.1f s, calibration %.1f s (%d bakes)"
          % ("%.0f s" % build if build is not None else "reused", doc["extract_seconds"], doc["calibrate_seconds"],
             len(doc["values"])), flush=True)


if __name__ == "__main__":
    if "--stage" in sys.argv and sys.argv[sys.argv.index("--stage") + 1] == "calibrate":
        stage_calibrate()
    else:
        main()

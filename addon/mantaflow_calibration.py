"""Calibrate a Mantaflow liquid domain's variational viscosity_value against reference silhouettes.

Run by a background Blender on a copy of the .blend (the Calibrate Mantaflow operator does this):

    blender -b --factory-startup COPY.blend --python mantaflow_calibration.py -- --domain NAME
        --engine EXE --reference DIR --camera CAMERA.json --scene SCENE.json --formula VALUE --out DIR

For each viscosity_value tried it bakes the domain into OUT/bakes/<value>/cache, writes the liquid
surface of every frame as OUT/bakes/<value>/surfaces/frame_%05d.obj (metres, world space, frame 0
= the scene's frame_start, the initial state, as the engine numbers its frames), scores them with
`viscoscope score` as identify scores its own simulations (same scene, ground band, frame mapping)
and writes OUT/calibration.json. Values: the formula's times --factors (powers of --step), extended
by --step while the best is the largest or smallest tried, then refined around the best with steps
√step, step^¼, … (--refine rounds). The value with the lowest E is chosen.

stdout carries one JSON object a line: progress events ({"event": "progress", "bake": i, "bakes": n,
...}) and a final {"event": "done", ...}. Bad input: one line on stderr, exit 2. SIGTERM: exit 3;
finished bakes are kept and a new run skips them.
"""

import argparse
import hashlib
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

if __package__:
    from .atomic_files import written_atomically
else:  # run as a script by the background Blender
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from atomic_files import written_atomically

EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT, EXIT_CANCELLED = 0, 1, 2, 3
VISCOSITY_VALUE_MIN, VISCOSITY_VALUE_MAX = 1e-6, 10.0  # RNA range of viscosity_value
FORMAT = "viscoscope.mantaflow_calibration"
FLAT_E_SHARE, FLAT_SPAN = 0.05, 2.0  # a plateau of E: within FLAT_E_SHARE of the least over FLAT_SPAN


class BadInput(Exception):
    pass


def emit(obj):
    sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
    sys.stdout.flush()


def finish(code, message=""):
    """Leave Blender at once with this exit code (Blender would print after a SystemExit)."""
    if message:
        sys.stderr.write(message.replace("\n", " ") + "\n")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def write_json(path, doc):
    with written_atomically(path) as fh:
        json.dump(doc, fh, indent=1, allow_nan=False)


def read_json(path):
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def digest(obj):
    return hashlib.sha1(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def file_digest(path):
    with open(path, "rb") as fh:
        return hashlib.sha1(fh.read()).hexdigest()[:16]


# --- values tried -------------------------------------------------------------------------------

def clamp_value(value):
    return min(max(value, VISCOSITY_VALUE_MIN), VISCOSITY_VALUE_MAX)


def same_value(a, b):
    return abs(math.log(a / b)) < 1e-3


def next_values(tried, step, refine_done, refine_rounds):
    """Values to bake next given {value: E}, and whether they are a refinement: extend past the
    best while it is the largest or smallest tried (and inside Mantaflow's range), then add the
    best × and ÷ step^(1/2^k) for refinement round k."""
    values = sorted(tried)
    best = min(values, key=lambda v: tried[v])
    if best == values[-1] and best < VISCOSITY_VALUE_MAX:
        return [clamp_value(best * step)], False
    if best == values[0] and best > VISCOSITY_VALUE_MIN:
        return [clamp_value(best / step)], False
    if refine_done >= refine_rounds:
        return [], False
    factor = step ** (0.5 ** (refine_done + 1))
    new = []
    for v in (clamp_value(best / factor), clamp_value(best * factor)):
        if not any(same_value(v, t) for t in values + new):
            new.append(v)
    return new, True


# --- the scene ------------------------------------------------------------------------------

def liquid_domain(name):
    import bpy
    obj = bpy.data.objects.get(name)
    if obj is None:
        raise BadInput("no object named '%s' in the scene" % name)
    for mod in obj.modifiers:
        if mod.type == 'FLUID' and mod.fluid_type == 'DOMAIN':
            if mod.domain_settings.domain_type != 'LIQUID':
                raise BadInput("'%s' is a Mantaflow gas domain, not a liquid domain" % name)
            return obj, mod.domain_settings
    raise BadInput("'%s' is not a Mantaflow liquid domain" % name)


def rna_values(struct):
    """The plain settings of an RNA struct (numbers, booleans, enums, strings), cache paths left out."""
    out = {}
    for prop in struct.bl_rna.properties:
        name = prop.identifier
        if prop.is_readonly or name.startswith("cache_") or name in ("viscosity_value", "use_viscosity"):
            continue
        if prop.type in {'BOOLEAN', 'INT', 'FLOAT', 'ENUM', 'STRING'}:
            value = getattr(struct, name)
            if prop.type == 'ENUM' and isinstance(value, set):
                value = sorted(value)
            elif prop.type in {'INT', 'FLOAT', 'BOOLEAN'} and getattr(prop, "array_length", 0):
                value = [round(x, 6) if isinstance(x, float) else x for x in value]
            elif isinstance(value, float):
                value = round(value, 6)
            out[name] = value
    return out


def scene_fingerprint(scene):
    """What a bake depends on besides viscosity_value: every fluid object's settings, place and mesh."""
    items = []
    for obj in sorted(scene.objects, key=lambda o: o.name):
        for mod in obj.modifiers:
            if mod.type != 'FLUID' or mod.fluid_type == 'NONE':
                continue
            settings = {'DOMAIN': mod.domain_settings, 'FLOW': mod.flow_settings,
                        'EFFECTOR': mod.effector_settings}[mod.fluid_type]
            items.append({"object": obj.name, "type": mod.fluid_type, "settings": rna_values(settings),
                          "matrix": [round(x, 7) for row in obj.matrix_world for x in row],
                          "vertices": len(getattr(obj.data, "vertices", ())),
                          "mesh": [round(x, 6) for v in getattr(obj.data, "vertices", ())[:64] for x in v.co]})
    return {"fluid_objects": items, "fps": scene.render.fps / scene.render.fps_base,
            "gravity": [round(x, 6) for x in scene.gravity], "use_gravity": scene.use_gravity,
            "scale_length": scene.unit_settings.scale_length}


def frame_mapping(manifest, fps, time_offset, last_source_frame):
    """(sim frame of the first reference frame, frames to bake after frame 0, compared count) as
    identify maps them: reference time t is simulation frame round((t + time_offset)·fps); frames with
    weight 0, before time 0 or past the job's frame range are left out (their weight set to 0)."""
    frames, times, weights = manifest["frames"], manifest["times_s"], list(manifest["weights"])
    first = None
    last = 0
    for j, (frame, t, w) in enumerate(zip(frames, times, weights)):
        t_sim = t + time_offset
        if w <= 0 or frame - frames[0] > last_source_frame or not math.isfinite(t_sim) or t_sim < -1e-9:
            weights[j] = 0.0
            continue
        n = int(round(t_sim * fps))
        if first is None:
            first = n - j
        elif n != first + j:
            raise BadInput("reference frames do not fall on consecutive simulation frames (reference frame "
                           "%d is simulation frame %d): extract every frame at the scene's frame rate" % (frame, n))
        last = max(last, n)
    if first is None:
        raise BadInput("no reference frame to compare (all weights 0 or outside the scene's frame range)")
    return first, last, weights


def scored_reference(reference, weights, folder):
    """The reference as score reads it, with the weights identify gives its frames: a manifest in
    FOLDER whose masks are the reference's own files (absolute paths)."""
    manifest = read_json(os.path.join(reference, "manifest.json"))
    manifest["masks"] = [os.path.join(os.path.abspath(reference), m) for m in manifest["masks"]]
    if isinstance(manifest.get("exclude"), str):
        manifest["exclude"] = os.path.join(os.path.abspath(reference), manifest["exclude"])
    manifest["weights"] = weights
    os.makedirs(folder, exist_ok=True)
    write_json(os.path.join(folder, "manifest.json"), manifest)
    return folder


# --- one bake -------------------------------------------------------------------------------

class CacheWatcher(threading.Thread):
    """Reports how many frames Mantaflow has written while bake_all runs (it gives no callback)."""

    def __init__(self, folder, event, frames):
        super().__init__(daemon=True)
        self.folder, self.event, self.frames = folder, event, frames
        self.stop = threading.Event()

    def run(self):
        reported = -1
        while not self.stop.wait(1.0):
            data = os.path.join(self.folder, "data")
            done = len([f for f in os.listdir(data) if f.startswith("fluid_data_")]) if os.path.isdir(data) else 0
            done = min(done, self.frames)
            if done != reported:
                reported = done
                emit(dict(self.event, stage="bake", frame=done, frames=self.frames))


def write_obj(path, vertices, triangles):
    with written_atomically(path) as fh:
        fh.write("".join("v %.7g %.7g %.7g\n" % v for v in vertices))
        fh.write("".join("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in triangles))


def export_surfaces(scene, domain, folder, last):
    """The domain's liquid surface at frames frame_start … frame_start + last as frame_%05d.obj
    (metres, world space); returns the triangles per frame. A frame without liquid gets one
    zero-area triangle, which covers no pixel (score refuses an OBJ without faces)."""
    import bpy
    os.makedirs(folder, exist_ok=True)
    scale = scene.unit_settings.scale_length
    counts = []
    for k in range(last + 1):
        scene.frame_set(scene.frame_start + k)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = domain.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            mesh.calc_loop_triangles()
            mw = evaluated.matrix_world
            vertices = [tuple(scale * x for x in (mw @ v.co)) for v in mesh.vertices]
            triangles = [tuple(t.vertices) for t in mesh.loop_triangles]
        finally:
            evaluated.to_mesh_clear()
        counts.append(len(triangles))
        if not triangles:
            centre = tuple(scale * x for x in domain.matrix_world.translation)
            vertices, triangles = [centre, centre, centre], [(0, 1, 2)]
        write_obj(os.path.join(folder, "frame_%05d.obj" % k), vertices, triangles)
    return counts


def bake(scene, domain, ds, value, folder, last, event):
    """Bake frames frame_start … frame_start + last at this viscosity_value into FOLDER/cache and
    export the surfaces; returns (bake seconds, triangles per frame)."""
    import bpy
    cache = os.path.join(folder, "cache")
    shutil.rmtree(cache, ignore_errors=True)  # a bake cut short by a cancel
    # The variational viscosity alone is calibrated: the diffusion path, which Apply to Mantaflow
    # Domain also turns on, adds its own and scatters thick liquids (test_sample_scenes' caramel).
    ds.use_diffusion = False
    ds.use_viscosity = True
    ds.viscosity_value = value
    ds.use_mesh = True
    ds.cache_type = 'ALL'
    ds.cache_directory = cache
    ds.cache_frame_start = scene.frame_start
    ds.cache_frame_end = scene.frame_start + last
    watcher = CacheWatcher(cache, event, last + 1)
    watcher.start()
    t0 = time.perf_counter()
    try:
        with bpy.context.temp_override(object=domain, active_object=domain, selected_objects=[domain],
                                       selected_editable_objects=[domain], scene=scene):
            result = bpy.ops.fluid.bake_all()
    finally:
        watcher.stop.set()
        watcher.join()
    seconds = time.perf_counter() - t0
    if result != {'FINISHED'}:
        raise BadInput("the Mantaflow bake at viscosity_value %.4g failed (%s)" % (value, ", ".join(sorted(result))))
    counts = export_surfaces(scene, domain, os.path.join(folder, "surfaces"), last)
    if not any(counts):
        raise BadInput("the Mantaflow bake at viscosity_value %.4g produced no liquid: check the domain's "
                       "liquid flow objects" % value)
    if counts[0] == 0:
        raise BadInput("the Mantaflow bake at viscosity_value %.4g has no liquid at the first frame" % value)
    return seconds, counts


def score(args, surfaces, reference, sim_first, out):
    """E of a bake's surfaces against the reference, by `viscoscope score`, and the ground band (m) it
    left out: identify's default for the scene."""
    cmd = [args.engine, "score", "--camera", args.camera, "--reference", reference, "--sim", surfaces,
           "--scene", args.scene, "--identify-ground-band", "--sim-first", str(sim_first),
           "--out", out, "--progress", "none"]
    proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [l for l in proc.stderr.strip().splitlines() if l.strip()]
        reason = lines[-1] if lines else "exit %d" % proc.returncode
        raise (BadInput if proc.returncode == 2 else RuntimeError)("viscoscope score: " + reason)
    doc = read_json(os.path.join(out, "score.json"))
    if doc is None or "E" not in doc:
        raise RuntimeError("viscoscope score wrote no E in %s" % out)
    return float(doc["E"]), float(doc["ground_band_m"])


# --- the run -----------------------------------------------------------------------------------

def parse_args(argv):
    p = argparse.ArgumentParser(prog="mantaflow_calibration.py")
    p.add_argument("--domain", required=True, help="the Mantaflow liquid domain object")
    p.add_argument("--engine", required=True, help="the viscoscope executable")
    p.add_argument("--reference", required=True, help="extracted silhouettes (manifest.json, masks/)")
    p.add_argument("--camera", required=True, help="camera JSON (viscoscope.blender_camera)")
    p.add_argument("--scene", required=True, help="the Viscoscope scene.json: solids that clip and hide")
    p.add_argument("--formula", type=float, required=True, help="the formula's viscosity_value, ν·0.4 s/L²")
    p.add_argument("--out", required=True)
    p.add_argument("--factors", default="0.25,1,4", help="first values, × the formula's")
    p.add_argument("--step", type=float, default=4.0, help="factor between values when bracketing")
    p.add_argument("--refine", type=int, default=2, help="refinement rounds around the best")
    p.add_argument("--max-bakes", type=int, default=12)
    p.add_argument("--resolution", type=int, default=0, help="domain resolution_max (0: the domain's)")
    p.add_argument("--time-offset", type=float, default=0.0, help="simulation time at reference time 0, s")
    return p.parse_args(argv)


def check_inputs(args):
    if not (math.isfinite(args.formula) and args.formula > 0):
        raise BadInput("--formula: must be a positive viscosity_value, got %r" % args.formula)
    if not (args.step > 1.0):
        raise BadInput("--step: must be above 1")
    for name, path in (("reference silhouettes", os.path.join(args.reference, "manifest.json")),
                       ("camera", args.camera), ("scene", args.scene)):
        if not os.path.isfile(path):
            raise BadInput("%s not found: %s" % (name, path))
    if not (os.path.isfile(args.engine) and os.access(args.engine, os.X_OK)):
        raise BadInput("engine not found or not executable: %s" % args.engine)
    manifest = read_json(os.path.join(args.reference, "manifest.json"))
    if not isinstance(manifest, dict) or manifest.get("format") != "viscoscope.reference":
        raise BadInput("%s is not a viscoscope.reference manifest" % os.path.join(args.reference, "manifest.json"))
    for key in ("frames", "times_s", "weights", "masks"):
        if not isinstance(manifest.get(key), list) or len(manifest[key]) != len(manifest.get("frames") or [None]):
            raise BadInput("%s: %s missing or of the wrong length"
                           % (os.path.join(args.reference, "manifest.json"), key))
    scene_doc = read_json(args.scene)
    if not isinstance(scene_doc, dict):
        raise BadInput("%s is not JSON" % args.scene)
    try:
        factors = [float(x) for x in args.factors.split(",") if x.strip()]
    except ValueError:
        raise BadInput("--factors: comma-separated numbers expected, got %r" % args.factors) from None
    if not factors or min(factors) <= 0:
        raise BadInput("--factors: positive numbers expected, got %r" % args.factors)
    return manifest, factors


def calibration_warnings(tried):
    """Why the chosen value may be wrong, from E at every value tried ({value: E})."""
    values = sorted(tried)
    best = min(values, key=lambda v: tried[v])
    warnings = []
    if not values[0] < best < values[-1]:
        side = "largest" if best == values[-1] else "smallest"
        warnings.append("the best viscosity_value is the %s tried (%.4g): the match may lie beyond%s"
                        % (side, best, " Mantaflow's limit of 10" if best >= VISCOSITY_VALUE_MAX else " it"))
    # As identify doubts a flat objective: E within FLAT_E_SHARE of its least over a factor
    # FLAT_SPAN of values (the capture cup's short clip left such a plateau: FINDINGS).
    near = [v for v in values if tried[v] <= (1 + FLAT_E_SHARE) * tried[best]]
    if near[-1] / near[0] >= FLAT_SPAN:
        warnings.append("E is within %d %% of its least from %.4g to %.4g: the footage hardly tells these "
                        "values apart (a longer clip would)" % (round(100 * FLAT_E_SHARE), near[0], near[-1]))
    return warnings


def run(args):
    import bpy
    manifest, factors = check_inputs(args)
    scene = bpy.context.scene
    domain, ds = liquid_domain(args.domain)
    if args.resolution:
        ds.resolution_max = args.resolution
    fps = scene.render.fps / scene.render.fps_base
    first, last, weights = frame_mapping(manifest, fps, args.time_offset, scene.frame_end - scene.frame_start)
    os.makedirs(args.out, exist_ok=True)
    reference = scored_reference(args.reference, weights, os.path.join(args.out, "reference"))
    bake_key = {"fingerprint": digest(scene_fingerprint(scene)), "resolution": ds.resolution_max,
                "frame_start": scene.frame_start, "frames": last + 1}
    score_key = {"reference": file_digest(os.path.join(reference, "manifest.json")),
                 "camera": file_digest(args.camera), "scene": file_digest(args.scene),
                 "sim_first": first}

    tried = {}   # value → E
    records = {}
    queue = [clamp_value(args.formula * f) for f in factors]
    refine_done = 0
    index = 0
    planned = len(queue) + 2 * args.refine  # as if the first values bracket the best, for progress
    while index < args.max_bakes:
        while not queue:
            queue, refining = next_values(tried, args.step, refine_done, args.refine)
            if not queue and not refining:
                break
            refine_done += refining
            planned += 0 if refining else len(queue)
        if not queue:
            break
        value = queue.pop(0)
        if any(same_value(value, v) for v in tried):
            continue
        index += 1
        ds.viscosity_value = value
        value = ds.viscosity_value  # as Blender stores it (single precision)
        folder = os.path.join(args.out, "bakes", "%.6g" % value)
        planned = max(planned, index + len(queue))
        event = {"event": "progress", "stage": "bake", "bake": index, "bakes": min(planned, args.max_bakes),
                 "viscosity_value": value}
        if tried:
            best = min(tried, key=tried.get)
            event.update(best_value=best, best_E=tried[best])
        record = read_json(os.path.join(folder, "bake.json")) or {}
        reused = record.get("key") == dict(bake_key, viscosity_value=value) and \
            record.get("score_key") == score_key and \
            all(isinstance(record.get(k), (int, float)) for k in ("E", "ground_band_m"))
        if not reused:
            emit(dict(event, frame=0, frames=last + 1))
            seconds, counts = bake(scene, domain, ds, value, folder, last, event)
            emit(dict(event, stage="score", frame=last + 1, frames=last + 1))
            E, band = score(args, os.path.join(folder, "surfaces"), reference, first, os.path.join(folder, "score"))
            record = {"key": dict(bake_key, viscosity_value=value), "score_key": score_key, "E": E, "ground_band_m": band,
                      "bake_seconds": seconds, "triangles": counts}
            write_json(os.path.join(folder, "bake.json"), record)
            shutil.rmtree(os.path.join(folder, "cache"), ignore_errors=True)  # the surfaces are kept
        tried[value] = record["E"]
        records[value] = {"viscosity_value": value, "E": record["E"], "ground_band_m": record["ground_band_m"],
                          "bake_seconds": record["bake_seconds"],
                          "reused": reused, "score": os.path.join(folder, "score", "score.json")}
        best = min(tried, key=tried.get)
        emit(dict(event, stage="scored", frame=last + 1, frames=last + 1, E=record["E"],
                  best_value=best, best_E=tried[best], reused=reused))

    values = sorted(tried)
    best = min(values, key=lambda v: tried[v])
    bracketed = values[0] < best < values[-1]
    doc = {
        "format": FORMAT, "version": 1, "domain": domain.name, "resolution": ds.resolution_max,
        "frames": last + 1, "sim_first": first, "fps": fps,
        "ground_band_m": records[best]["ground_band_m"],
        "formula_value": args.formula, "chosen_value": best, "ratio": best / args.formula,
        "E": tried[best], "bracketed": bracketed,
        "values": [records[v] for v in values],
    }
    warnings = calibration_warnings(tried)
    for warning in warnings:
        emit({"event": "warning", "message": warning})
    if warnings:
        doc["warning"] = "; ".join(warnings)
    write_json(os.path.join(args.out, "calibration.json"), doc)
    emit({"event": "done", "formula_value": args.formula, "chosen_value": best, "ratio": best / args.formula,
          "E": tried[best], "bakes": len(values)})


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    signal.signal(signal.SIGTERM, lambda *_: finish(EXIT_CANCELLED, "cancelled; finished bakes are kept"))
    try:
        args = parse_args(argv)
    except SystemExit as exc:  # argparse has printed its one line
        finish(EXIT_BAD_INPUT if exc.code else EXIT_OK)
    try:
        run(args)
    except BadInput as exc:
        finish(EXIT_BAD_INPUT, "error: %s" % exc)
    except (OSError, RuntimeError) as exc:
        finish(EXIT_INTERNAL, "error: %s" % exc)
    except Exception as exc:  # noqa: BLE001  (a bug: still one line, and Blender must not stay open)
        finish(EXIT_INTERNAL, "internal error: %s: %s" % (type(exc).__name__, exc))
    finish(EXIT_OK)


if __name__ == "__main__":
    main()

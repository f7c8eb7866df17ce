"""Identify: run the engine's identification out of process (cancel keeps its checkpoint, Resume
continues it), then show the result."""

import json
import math
import os

import bpy

from .. import engine, prefs, scene_export, schema, units
from ..atomic_files import written_atomically
from .runner import EngineOperator, is_running, start_afresh
from .silhouettes import extraction_settings, reference_video

JOB_FORMAT = "viscoscope.job"
JOB_VERSION = 1


# The viscosity search's bounds (Pa·s): written into the job and used to flag an interval that reaches them.
ETA_BOUNDS = schema.search_bounds("viscosity")
# The engine wants a cup's hole at least this many cells across: coarser, the cup drains at the wrong
# rate and η comes out wrong with it.
MIN_HOLE_CELLS = schema.MIN_HOLE_CELLS


def identify_dir(scene):
    return os.path.join(scene_export.work_dir(scene), "identify")


def needed_resolution(scene_dict):
    """The smallest grid resolution at which every cup's hole spans MIN_HOLE_CELLS cells (0: no cup)."""
    extent = max(hi - lo for lo, hi in zip(scene_dict["domain"]["min"], scene_dict["domain"]["max"]))
    holes = [s["hole_radius"] for s in scene_dict["solids"] if s["type"] == "cup" and s["hole_radius"] > 0]
    return max((math.ceil(MIN_HOLE_CELLS * extent / (2 * r) - 1e-9) for r in holes), default=0)


def identify_resolution(scene, scene_dicts):
    """(resolution for the job, note): the panel's, raised to what every run's cup hole needs."""
    asked = scene.viscoscope.identify_resolution
    needed = max(needed_resolution(d) for d in scene_dicts)
    if needed <= asked:
        return asked, ""
    return needed, "Resolution %d used: the cup's hole needs %.1f cells across" % (needed, MIN_HOLE_CELLS)


def measured_track(scene):
    """The Reference panel's measured track as a job's "track" (metres, the CSV's path absolute)."""
    vs = scene.viscoscope
    path = bpy.path.abspath(vs.track_csv) if vs.track_csv else ""
    if not path or not os.path.isfile(path):
        raise scene_export.ExportError("measured track CSV not found: %s" % (path or "none chosen"))
    column = vs.track_column
    if not column:
        try:
            with open(path, encoding="utf-8") as fh:
                header = fh.readline().strip().split(",")
        except (OSError, UnicodeDecodeError) as exc:
            raise scene_export.ExportError("cannot read measured track %s: %s" % (path, exc)) from exc
        if len(header) < 2:
            raise scene_export.ExportError("measured track %s: no measured column after time_s in its header" % path)
        column = header[1].strip()
    scale = scene.unit_settings.scale_length
    track = {"csv": path, "column": column, "observable": vs.track_observable,
             "origin": units.vec_to_metres(vs.track_origin, scale),
             "band": units.to_metres(vs.track_band, scale), "weight": vs.track_weight}
    if vs.track_observable == 'front':
        track["direction"] = list(vs.track_direction)
    return track


def run_scenes(scene):
    """The scenes whose references the job fits: this one, then the other runs of its liquid."""
    scenes = [scene]
    for k, run in enumerate(scene.viscoscope.runs):
        if run.scene is None:
            raise scene_export.ExportError("run %d has no scene: choose one or remove it" % (k + 2))
        if run.scene in scenes:
            raise scene_export.ExportError("scene '%s' is a run twice" % run.scene.name)
        scenes.append(run.scene)
    return scenes


def run_entry(scene, folder, prefix, fluid):
    """One run's keys of a job (its scene; its clip's camera, video and extraction, its measured
    track), with its files written into folder under names starting with prefix; and its scene dict.
    The material is `fluid`, which all runs of one liquid share."""
    vs = scene.viscoscope
    clip = vs.reference_kind in ('CLIP', 'BOTH')
    if clip and not vs.video_path:
        raise scene_export.ExportError("no reference video: load one in the Reference section")
    scene_dict = scene_export.export_scene(scene, os.path.join(folder, prefix + "scene.json"), fluid=fluid)
    entry = {"scene": prefix + "scene.json", "time_offset_s": vs.time_offset}
    if clip:
        from .camera import scene_camera
        scene_export.export_camera(scene_camera(scene), scene, os.path.join(folder, prefix + "blender_camera.json"))
        # Always the video with the panel's settings, never the preview's masks (which may be stale):
        # the engine extracts again whenever the video or these settings change.
        entry.update({"camera": prefix + "blender_camera.json", "video": reference_video(scene),
                      "extraction": extraction_settings(scene),
                      "frame_start": scene.frame_start, "frame_end": scene.frame_end})
    if vs.reference_kind in ('TRACK', 'BOTH'):
        entry["track"] = measured_track(scene)
    return entry, scene_dict


def write_job(context, folder):
    """Export every run's scene (and camera, for a clip) and write job.json; returns (its path, a note
    for the panel or "")."""
    scene = context.scene
    vs = scene.viscoscope
    os.makedirs(folder, exist_ok=True)
    entries, scene_dicts = [], []
    for k, run in enumerate(run_scenes(scene)):
        try:
            entry, scene_dict = run_entry(run, folder, "run%d_" % k if k else "", vs.fluid)
        except scene_export.ExportError as exc:
            raise scene_export.ExportError("run '%s': %s" % (run.name, exc) if k else str(exc)) from exc
        entries.append(entry)
        scene_dicts.append(scene_dict)
    resolution, note = identify_resolution(scene, scene_dicts)
    job = {
        "format": JOB_FORMAT, "version": JOB_VERSION,
        "forward_model": vs.forward_model,
        # The job's spread s is absolute, searched as ln(1 + s/initial); the panel's is a factor f of η.
        "parameters": [{"name": "viscosity", "initial": vs.eta_initial,
                        "spread": vs.eta_initial * (vs.eta_spread - 1.0),
                        "min": ETA_BOUNDS[0], "max": ETA_BOUNDS[1], "log": True}],
        "resolution": resolution,
        "max_generations": vs.max_generations,
        "time_budget_s": vs.time_budget_minutes * 60.0,
        "seed": vs.sim_seed,
    }
    if len(entries) == 1:
        job.update(entries[0])
    else:
        job["runs"] = entries
    if vs.forward_model != 'thin_film':  # the thin film has no grid to place
        job.update({"grid_placements": vs.grid_placements, "grid_placement_schedule": vs.placement_schedule})
    path = os.path.join(folder, "job.json")
    with written_atomically(path) as fh:
        json.dump(job, fh, indent=1, allow_nan=False)
    return path, note


def reference_name(scene):
    """The references' file names, every run's, as a result records where it came from."""
    names = []
    for run in run_scenes(scene):
        vs = run.viscoscope
        if vs.reference_kind in ('CLIP', 'BOTH'):
            names.append(bpy.path.basename(vs.video_path))
        if vs.reference_kind in ('TRACK', 'BOTH'):
            names.append(bpy.path.basename(vs.track_csv))
    return " and ".join(names)


def bound_doubts(low, high):
    """The add-on's own doubt: an interval that reaches a search bound did not find η inside them."""
    out = []
    for name, end in (("low", low), ("high", high)):
        for bound in ETA_BOUNDS:
            if math.isclose(end, bound, rel_tol=1e-6):
                out.append("The interval's %s end (%.4g Pa·s) is the search bound: η may lie beyond it" % (name, end))
    return out


def read_result(context, out_dir):
    """Read DIR/result.json into the Results section. The Fluid Material takes η only when nothing
    casts doubt on it; otherwise the panel shows why and offers Apply Anyway."""
    path = os.path.join(out_dir, "result.json")
    with open(path, encoding="utf-8") as fh:
        result = json.load(fh)
    vs = context.scene.viscoscope
    viscosity = result.get("viscosity")
    if not isinstance(viscosity, dict) or "value" not in viscosity or len(viscosity.get("interval", ())) != 2:
        raise ValueError("%s has no viscosity with an interval" % path)
    eta = float(viscosity["value"])
    low, high = (float(x) for x in viscosity["interval"])
    doubts = [str(d) for d in result.get("doubts") or ()]  # an older engine writes none
    doubts += bound_doubts(low, high)
    vs.result_eta, vs.result_eta_low, vs.result_eta_high = eta, low, high
    vs.result_footage = reference_name(context.scene)
    vs.result_doubts = "\n".join(doubts)
    vs.result_applied = False
    if not doubts:
        apply_identified_eta(vs)
    for name in ("convergence.png", "landscape.png"):
        png = os.path.join(out_dir, name)
        if os.path.isfile(png):
            img = bpy.data.images.load(png, check_existing=True)
            img.reload()
            img.preview_ensure()


def apply_identified_eta(vs):
    """η into the Fluid Material, with the footage and interval it came from (a preset keeps them)."""
    vs.fluid.viscosity = vs.result_eta  # clears the material's identified_from: set it after
    vs.fluid.identified_from = "%s: η %.4g Pa·s, interval %.4g–%.4g Pa·s%s" % (
        vs.result_footage, vs.result_eta, vs.result_eta_low, vs.result_eta_high,
        ", applied despite the engine's doubts" if vs.result_doubts else "")
    vs.result_applied = True


class VISCOSCOPE_OT_apply_result(bpy.types.Operator):
    """Write the identified η into the Fluid Material although the engine doubts it"""
    bl_idname = "viscoscope.apply_result"
    bl_label = "Apply Anyway"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        vs = context.scene.viscoscope
        return vs.result_eta > 0.0 and not vs.result_applied

    def execute(self, context):
        vs = context.scene.viscoscope
        apply_identified_eta(vs)
        self.report({'INFO'}, "η = %.4g Pa·s applied to the Fluid Material" % vs.result_eta)
        return {'FINISHED'}


class JobOperator(EngineOperator):
    """Writes the panel's job into folder(scene) and runs one engine command on it into its out/ (a
    fresh run forgets the earlier run's checkpoints; Resume goes on from them)."""
    resume = False
    run_name = ""  # what the command makes, as "nothing to resume: no … in DIR" names it

    @classmethod
    def poll(cls, context):
        return not is_running(cls.job_kind)

    folder = None  # staticmethod(scene → the folder of the job and its out/)
    engine_args = None  # (exe, job, out_dir, threads) → the engine's arguments (a staticmethod or a method)

    def prepare(self, context):
        exe = prefs.find_engine(context)
        folder = self.folder(context.scene)
        out_dir = os.path.join(folder, "out")
        if self.resume and not os.path.isdir(out_dir):
            raise engine.EngineError("nothing to resume: no %s in %s" % (self.run_name, out_dir))
        job, self.note = write_job(context, folder)
        if not self.resume:
            start_afresh(out_dir)
        return self.engine_args(exe, job, out_dir, prefs.threads(context)), out_dir


class _IdentifyBase(JobOperator):
    job_kind = "identify"
    run_name = "identification"

    folder = staticmethod(identify_dir)
    engine_args = staticmethod(engine.identify_args)

    def on_success(self, context, out_dir):
        read_result(context, out_dir)


class VISCOSCOPE_OT_identify(_IdentifyBase, bpy.types.Operator):
    """Identify the viscosity from the reference video (runs in the background; Esc cancels)"""
    bl_idname = "viscoscope.identify"
    bl_label = "Identify Viscosity"


class VISCOSCOPE_OT_identify_resume(_IdentifyBase, bpy.types.Operator):
    """Continue a cancelled identification from its checkpoint"""
    bl_idname = "viscoscope.identify_resume"
    bl_label = "Resume"
    resume = True


class VISCOSCOPE_OT_load_fields(bpy.types.Operator):
    """Import the best simulation's hidden fields (.vdb sequence: surface, velocity, pressure) as a Volume object"""
    bl_idname = "viscoscope.load_fields"
    bl_label = "Load Hidden Fields"
    bl_options = {'REGISTER', 'UNDO'}

    directory: bpy.props.StringProperty(subtype='DIR_PATH', default="")

    def execute(self, context):
        from .simulate import import_result
        base = self.directory or context.scene.viscoscope.identify_job.out_dir
        candidates = [os.path.join(base, "fields"), os.path.join(base, "best"), base]
        for folder in candidates:
            try:
                obj = import_result(context, bpy.path.abspath(folder))
            except FileNotFoundError:
                continue
            obj.name = "Viscoscope Hidden Fields"
            return {'FINISHED'}
        self.report({'ERROR'}, "No frame_*.vdb found under %s" % base)
        return {'CANCELLED'}


classes = (VISCOSCOPE_OT_identify, VISCOSCOPE_OT_identify_resume, VISCOSCOPE_OT_apply_result,
           VISCOSCOPE_OT_load_fields)

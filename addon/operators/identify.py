"""Identify: run the engine's identification out of process (cancel keeps its checkpoint, Resume
continues it), then show the result."""

import json
import math
import os

import bpy

from .. import engine, prefs, scene_export, schema
from ..atomic_files import written_atomically
from .runner import EngineOperator, is_running
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


def identify_resolution(scene, scene_dict):
    """(resolution for the job, note): the panel's, raised to what the cup's hole needs."""
    asked = scene.viscoscope.identify_resolution
    needed = needed_resolution(scene_dict)
    if needed <= asked:
        return asked, ""
    return needed, "Resolution %d used: the cup's hole needs %.1f cells across" % (needed, MIN_HOLE_CELLS)


def write_job(context, folder):
    """Export scene + camera and write job.json; returns (its path, a note for the panel or "")."""
    scene = context.scene
    vs = scene.viscoscope
    if not vs.video_path:
        raise scene_export.ExportError("no reference video: load one in the Reference section")
    video = reference_video(scene)
    from .camera import scene_camera
    os.makedirs(folder, exist_ok=True)
    scene_dict = scene_export.export_scene(scene, os.path.join(folder, "scene.json"))
    scene_export.export_camera(scene_camera(context), scene, os.path.join(folder, "blender_camera.json"))
    resolution, note = identify_resolution(scene, scene_dict)
    job = {
        "format": JOB_FORMAT, "version": JOB_VERSION,
        "scene": "scene.json",
        "camera": "blender_camera.json",
        # Always the video with the panel's settings, never the preview's masks (which may be stale):
        # the engine extracts again whenever the video or these settings change.
        "video": video,
        "extraction": extraction_settings(scene),
        "frame_start": scene.frame_start, "frame_end": scene.frame_end,
        # The job's spread s is absolute, searched as ln(1 + s/initial); the panel's is a factor f of η.
        "parameters": [{"name": "viscosity", "initial": vs.eta_initial,
                        "spread": vs.eta_initial * (vs.eta_spread - 1.0),
                        "min": ETA_BOUNDS[0], "max": ETA_BOUNDS[1], "log": True}],
        "resolution": resolution,
        "max_generations": vs.max_generations,
        "grid_placements": vs.grid_placements,
        "grid_placement_schedule": vs.placement_schedule,
        "time_budget_s": vs.time_budget_minutes * 60.0,
        "seed": vs.sim_seed,
    }
    path = os.path.join(folder, "job.json")
    with written_atomically(path) as fh:
        json.dump(job, fh, indent=1, allow_nan=False)
    return path, note


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
    vs.result_footage = bpy.path.basename(vs.video_path)
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


class _IdentifyBase(EngineOperator):
    job_kind = "identify"
    resume = False

    @classmethod
    def poll(cls, context):
        return not is_running("identify")

    def prepare(self, context):
        exe = prefs.find_engine(context)
        folder = identify_dir(context.scene)
        out_dir = os.path.join(folder, "out")
        if self.resume and not os.path.isdir(out_dir):
            raise engine.EngineError("nothing to resume: no identification in %s" % out_dir)
        job, self.note = write_job(context, folder)
        return engine.identify_args(exe, job, out_dir, prefs.threads(context)), out_dir

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

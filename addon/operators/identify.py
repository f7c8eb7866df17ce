"""Identify: run the engine's identification out of process (cancel keeps its checkpoint, Resume
continues it), then show the result."""

import json
import os

import bpy

from .. import engine, prefs, scene_export
from .runner import EngineOperator, is_running

JOB_FORMAT = "viscoscope.job"
JOB_VERSION = 1


def identify_dir(scene):
    return os.path.join(scene_export.work_dir(scene), "identify")


def write_job(context, folder):
    """Export scene + camera and write job.json; returns its path."""
    scene = context.scene
    vs = scene.viscoscope
    if not vs.video_path:
        raise scene_export.ExportError("no reference video: load one in the Reference section")
    video = bpy.path.abspath(vs.video_path)
    if not os.path.isfile(video):
        raise scene_export.ExportError("reference video not found: %s" % video)
    from .camera import scene_camera
    os.makedirs(folder, exist_ok=True)
    scene_export.export_scene(scene, os.path.join(folder, "scene.json"))
    scene_export.export_camera(scene_camera(context), scene, os.path.join(folder, "blender_camera.json"))
    masks = os.path.join(scene_export.work_dir(scene), "silhouettes")
    job = {
        "format": JOB_FORMAT, "version": JOB_VERSION,
        "scene": "scene.json",
        "camera": "blender_camera.json",
        "video": video,
        "silhouettes": masks if os.path.isfile(os.path.join(masks, "manifest.json")) else None,
        "frame_start": scene.frame_start, "frame_end": scene.frame_end,
        # The job's spread s is absolute, searched as ln(1 + s/initial); the panel's is a factor f of η.
        "parameters": [{"name": "viscosity", "initial": vs.eta_initial,
                        "spread": vs.eta_initial * (vs.eta_spread - 1.0), "min": 1e-3, "max": 1e4, "log": True}],
        "resolution": vs.identify_resolution,
        "max_generations": vs.max_generations,
        "grid_placements": vs.grid_placements,
        "grid_placement_schedule": vs.placement_schedule,
        "time_budget_s": vs.time_budget_minutes * 60.0,
        "seed": vs.sim_seed,
    }
    path = os.path.join(folder, "job.json")
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(job, fh, indent=1, allow_nan=False)
    return path


def read_result(context, out_dir):
    """Read DIR/result.json into the Results section."""
    path = os.path.join(out_dir, "result.json")
    with open(path, encoding="utf-8") as fh:
        result = json.load(fh)
    vs = context.scene.viscoscope
    viscosity = result.get("viscosity")
    if not isinstance(viscosity, dict) or "value" not in viscosity or len(viscosity.get("interval", ())) != 2:
        raise ValueError("%s has no viscosity with an interval" % path)
    eta = float(viscosity["value"])
    vs.result_eta = eta
    vs.result_eta_low, vs.result_eta_high = (float(x) for x in viscosity["interval"])
    vs.fluid.viscosity = eta
    for name in ("convergence.png", "landscape.png"):
        png = os.path.join(out_dir, name)
        if os.path.isfile(png):
            img = bpy.data.images.load(png, check_existing=True)
            img.reload()
            img.preview_ensure()


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
        job = write_job(context, folder)
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


classes = (VISCOSCOPE_OT_identify, VISCOSCOPE_OT_identify_resume, VISCOSCOPE_OT_load_fields)

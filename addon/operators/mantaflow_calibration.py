"""Calibrate Mantaflow to Footage: bake Blender's own liquid solver at several viscosity_values in a
background Blender (addon/mantaflow_calibration.py), score each bake's silhouettes against the
reference as identify scores its own simulations, and set the domain's viscosity_value to the best.

The formula's value (ν·0.4 s/L², what Apply to Mantaflow Domain sets) is where the search starts; on
clips of the capture cup it drained far faster than the engine at the same η (issue 65 §3).
"""

import json
import os

import bpy

from .. import engine, mantaflow, prefs, scene_export, units
from . import fluid as fluid_ops
from .identify import identify_dir
from .runner import EngineOperator, is_running

DRIVER = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "mantaflow_calibration.py")
KIND = "calibrate"


def calibration_dir(scene):
    return os.path.join(scene_export.work_dir(scene), "calibrate_mantaflow")


def liquid_domain(context):
    """The active object when it is a Mantaflow liquid domain, else the scene's only one."""
    def is_liquid_domain(obj):
        mod = mantaflow.fluid_modifier(obj)
        return mod is not None and mod.fluid_type == 'DOMAIN' and mod.domain_settings.domain_type == 'LIQUID'
    active = context.active_object
    if is_liquid_domain(active):
        return active
    found = [obj for obj in context.scene.objects if is_liquid_domain(obj)]
    if len(found) == 1:
        return found[0]
    if not found:
        raise scene_export.ExportError("no Mantaflow liquid domain in the scene: add one (Physics > Fluid > "
                                       "Domain, type Liquid) with the liquid as a Flow object")
    raise scene_export.ExportError("%d Mantaflow liquid domains: select the one to calibrate" % len(found))


def reference_silhouettes(scene):
    """The extracted reference: the Identify job's, else the Preview's."""
    for folder in (os.path.join(identify_dir(scene), "out", "reference"),
                   os.path.join(scene_export.work_dir(scene), "silhouettes")):
        if os.path.isfile(os.path.join(folder, "manifest.json")):
            return folder
    raise scene_export.ExportError("no reference silhouettes: run Identify or Preview Silhouettes first")


def formula_value(context, domain):
    """What Apply to Mantaflow Domain would set, before clamping: ν·0.4 s/L², and the η it takes
    (a shear-dependent material's at the typical shear rate)."""
    scene = context.scene
    fluid = scene.viscoscope.fluid
    stand_in = fluid_ops.mantaflow_stand_in(context, domain)
    eta = fluid.viscosity if stand_in is None else stand_in[1]
    nu = units.kinematic_viscosity(eta, fluid.density)
    try:
        value, _clamped = mantaflow.variational_value(domain, nu, scene.unit_settings.scale_length)
    except mantaflow.DomainError as exc:
        raise scene_export.ExportError(str(exc)) from exc
    if not value > 0:
        raise scene_export.ExportError("the Fluid Material's viscosity is 0: set η before calibrating")
    return value, eta


def driver_args(exe, copy, domain_name, reference, camera, scene_json, formula, out_dir, time_offset, threads=0):
    args = [bpy.app.binary_path, "-b"]
    if threads:
        args += ["-t", str(threads)]
    return args + ["--factory-startup", copy, "--python-exit-code", str(engine.EXIT_INTERNAL),
                   "--python", DRIVER, "--",
                   "--domain", domain_name, "--engine", exe, "--reference", reference, "--camera", camera,
                   "--scene", scene_json, "--formula", repr(formula), "--out", out_dir,
                   "--time-offset", repr(time_offset)]


def read_calibration(context, out_dir):
    """calibration.json → the domain's viscosity_value and the panel's summary."""
    with open(os.path.join(out_dir, "calibration.json"), encoding="utf-8") as fh:
        doc = json.load(fh)
    obj = bpy.data.objects.get(doc["domain"])
    if obj is None:
        raise KeyError("domain '%s' is gone" % doc["domain"])
    ds = mantaflow.domain_settings(obj)
    mantaflow.set_domain_setting(ds, "use_diffusion", False)  # as the calibration baked it
    mantaflow.set_domain_setting(ds, "use_viscosity", True)
    mantaflow.set_domain_setting(ds, "viscosity_value", min(float(doc["chosen_value"]), mantaflow.VISCOSITY_VALUE_MAX))
    # The formula's value no longer follows the domain's size: the calibration holds for this domain.
    if mantaflow.NU_KEY in obj:
        del obj[mantaflow.NU_KEY]
    summary = {key: doc[key] for key in ("domain", "resolution", "formula_value", "chosen_value", "ratio",
                                         "bracketed")}
    summary["values"] = [[v["viscosity_value"], v["E"]] for v in doc["values"]]
    summary["warning"] = doc.get("warning", "")
    context.scene.viscoscope.mantaflow_calibration = json.dumps(summary)


class VISCOSCOPE_OT_calibrate_mantaflow(EngineOperator, bpy.types.Operator):
    """Bake the Mantaflow liquid domain at several viscosity_values around the formula's, score each against the reference silhouettes and set the best (runs in the background; Esc cancels, a new run keeps finished bakes)"""
    bl_idname = "viscoscope.calibrate_mantaflow"
    bl_label = "Calibrate Mantaflow to Footage"
    job_kind = KIND

    @classmethod
    def poll(cls, context):
        return not is_running(KIND)

    def prepare(self, context):
        scene = context.scene
        vs = scene.viscoscope
        exe = prefs.find_engine(context)
        domain = liquid_domain(context)
        reference = reference_silhouettes(scene)
        cam = vs.camera or scene.camera
        if cam is None or cam.type != 'CAMERA':
            raise scene_export.ExportError("no camera: choose one in the Camera section")
        formula, eta = formula_value(context, domain)
        folder = calibration_dir(scene)
        os.makedirs(folder, exist_ok=True)
        camera_json = os.path.join(folder, "blender_camera.json")
        scene_json = os.path.join(folder, "scene.json")
        scene_export.export_camera(cam, scene, camera_json)
        scene_export.export_scene(scene, scene_json)
        copy = os.path.join(folder, "scene_copy.blend")
        try:
            bpy.ops.wm.save_as_mainfile(filepath=copy, copy=True, check_existing=False)
        except RuntimeError as exc:
            reason = str(exc).strip().splitlines()[-1]
            raise engine.EngineError("cannot save a copy of the .blend: %s" % reason) from exc
        self.note = "From the formula's viscosity_value %.4g (η %.4g Pa·s, ρ %.4g kg/m³), resolution %d" % (
            formula, eta, vs.fluid.density, mantaflow.domain_settings(domain).resolution_max)
        out_dir = os.path.join(folder, "out")
        return driver_args(exe, copy, domain.name, reference, camera_json, scene_json, formula, out_dir,
                           vs.time_offset, prefs.threads(context)), out_dir

    def on_success(self, context, out_dir):
        read_calibration(context, out_dir)


classes = (VISCOSCOPE_OT_calibrate_mantaflow,)

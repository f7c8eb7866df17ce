"""Diagnose: run the engine's diagnosis out of process (the same job Identify writes; cancel keeps
each fit's checkpoint, Resume continues), show its conclusion and figures, and Apply Effect writes
the chosen model's material into the Fluid Material."""

import json
import math
import os
import re

import bpy

from .. import engine, schema, scene_export
from .identify import JobOperator, reference_name

DIAGNOSIS_FORMAT = "viscoscope.diagnosis"
# The engine's "type" of a material model → the Fluid Material's model.
MODEL_ITEMS = {engine_type: item for item, engine_type in scene_export.MODEL_TYPES.items()}


def diagnose_dir(scene):
    return os.path.join(scene_export.work_dir(scene), "diagnose")


def describe_parameter(name, fit):
    """'K 18.76 Pa·sⁿ [16.01–22.07]' from a parameter's name ("solids[0].width" too) and its fit."""
    declared = schema.PARAMETERS.get(re.sub(r"^solids\[\d+\]\.", "", name))
    symbol, unit = (declared["symbol"], declared["unit"]) if declared else (name, "")
    unit = "" if unit in ("", "1") else " " + unit
    low, high = fit.get("interval") or (float("nan"), float("nan"))
    return "%s %.4g%s [%.4g–%.4g]" % (symbol, fit["value"], unit, low, high)


def describe_model(entry):
    """One line of a fitted model: its parameters, its error on the held-out frames, its BIC."""
    parameters = ", ".join(describe_parameter(name, fit) for name, fit in sorted(entry["parameters"].items()))
    line = "%s: %s; held-out E %.3g, BIC %.1f" % (entry.get("title", entry["model"]).capitalize(),
                                                  parameters or "nothing searched", entry["held_out_E"], entry["bic"])
    if "track_error" in entry:
        line += ", track error %.2f %%" % (100 * entry["track_error"])
    if "earns_its_parameters" in entry:
        line += "; earns its parameters" if entry["earns_its_parameters"] else "; does not earn its parameters"
    if entry.get("effect_vanishes"):
        line += " (it ended where its effect vanishes: the base model)"
    for doubt in entry["doubts"]:
        line += "; doubted: " + doubt
    return line


def describe_errors(errors):
    """'Error before → after: …' per observable the diagnosis compares."""
    parts = ["E %.3g → %.3g" % (errors["E"]["before"], errors["E"]["after"]),
             "held-out E %.3g → %.3g" % (errors["held_out_E"]["before"], errors["held_out_E"]["after"])]
    if "track_error" in errors:
        parts.append("track %.2f %% → %.2f %%" % (100 * errors["track_error"]["before"],
                                                  100 * errors["track_error"]["after"]))
    return "Error before → after: " + "; ".join(parts)


def describe_noise_floor(noise):
    """The noise floor in one line: how much the simulation alone moves the held-out E."""
    if noise["deterministic"]:
        return "Noise floor: none (the forward model is deterministic)"
    scorings = len(noise["held_out_E"])
    if scorings < 2:
        return "Noise floor: not measured (one scoring of the base's best fit)"
    return ("Noise floor: the base's held-out E scatters by a factor %.2f over %d seeds and grid placements; "
            "gains under %.0f %% are within it" % (math.exp(noise["log_spread"]), scorings, 100 * noise["visible_share"]))


def describe_cross_run(candidate):
    """A candidate fitted to each run alone, in one line: how well it predicts the other runs."""
    cross = candidate["cross_run"]
    gain = cross.get("gain")
    said = "not compared" if gain is None else "%.0f %% %s than the base's" % (100 * abs(gain), "better" if gain >= 0 else "worse")
    return "%s fitted to each run alone predicts the other runs %s (E %.4g)" % (candidate["model"], said, cross["E"])


def describe_flow_curve(curve):
    """The answer's flow curve in one line: its shear rates and how far it lies from the rheometer's."""
    low, high = curve["shear_rate_range_per_s"]
    line = "Flow curve of %s over %.3g–%.3g 1/s, the shear rates its flow exercised" % (curve["model"], low, high)
    rms = (curve.get("rheometer") or {}).get("log_stress_rms")
    if rms is not None:
        line += "; %.2f off the rheometer's (log10 of stress, RMS)" % rms
    elif curve.get("rheometer"):
        line += "; the rheometer's curve does not reach these shear rates"
    return line


def read_diagnosis(context, out_dir):
    """DIR/diagnosis.json into the Diagnose panel; diagnosis.png as its preview."""
    path = os.path.join(out_dir, "diagnosis.json")
    with open(path, encoding="utf-8") as fh:
        doc = json.load(fh)
    if not isinstance(doc, dict) or doc.get("format") != DIAGNOSIS_FORMAT:
        raise ValueError("%s is not a diagnosis (format %r)" % (path, doc.get("format") if isinstance(doc, dict) else None))
    chosen = doc["chosen"]
    models = [doc["base"]] + list(doc["candidates"])
    after = next((m for m in models[1:] if m["model"] == chosen), None) if chosen else doc["base"]
    if after is None:
        raise ValueError("%s chose %r, which is not among its candidates" % (path, chosen))
    lines = ["What would tell: %s" % t for t in doc["what_would_tell"]]
    lines += ["Warning: %s" % w for w in doc.get("warnings", ())]
    lines += [describe_noise_floor(doc["noise_floor"]), describe_errors(doc["errors"])]
    lines += [describe_model(m) for m in models]
    lines += ["Run %d alone: %s" % (entry["run"], describe_model(entry)) for entry in doc.get("base_per_run", ())]
    if doc.get("runs_disagree"):
        lines.append("The runs disagree: " + doc["runs_disagree"])
    lines += [describe_cross_run(c) for c in doc["candidates"] if c.get("cross_run")]
    if doc.get("flow_curve"):
        lines.append(describe_flow_curve(doc["flow_curve"]))
    refit = doc.get("base_refit")
    if refit:
        lines.append("The base refit from where %s's fit puts it %s; the other base fit: %s"
                     % (refit["from"], "replaced the first fit" if refit["replaced_first_fit"] else "did not better the first fit",
                        describe_model(refit["unused_fit"])))
    lines += ["%s not tried: %s" % (n["effect"], n["why"]) for n in doc.get("not_tried", ())]
    geometry = [name for name in after["parameters"] if name.startswith("solids[")] if chosen else []
    if geometry:
        lines.append("%s is geometry, not a property of the liquid: Apply Effect writes the material fitted "
                     "with it; scenes that should show the effect need the solid too (%s)"
                     % (chosen, ", ".join(describe_parameter(n, after["parameters"][n]) for n in geometry)))
    vs = context.scene.viscoscope
    grid = doc["grid"]
    vs.diagnosis_grid = "Ran at resolution %d on %d grid placement%s" % (
        grid["resolution"], grid["grid_placements"], "" if grid["grid_placements"] == 1 else "s")
    vs.diagnosis_suggested = json.dumps(doc["suggested_settings"])
    vs.diagnosis_conclusion = doc["conclusion"]
    vs.diagnosis_verdict = doc["verdict"]
    vs.diagnosis_effect = chosen or ""
    vs.diagnosis_report = "\n".join(lines)
    vs.diagnosis_material = json.dumps(after["material"]) if chosen else ""
    vs.diagnosis_source = "%s: %s; %s" % (reference_name(context.scene), describe_model(after), describe_errors(doc["errors"]))
    vs.diagnosis_applied = False
    png = os.path.join(out_dir, "diagnosis.png")
    if os.path.isfile(png):
        img = bpy.data.images.load(png, check_existing=True)
        img.reload()
        img.preview_ensure()


def apply_material(fluid, material):
    """The engine's "material" (a scene file's) into the Fluid Material: every declared parameter the
    panel holds, and the model."""
    model = material["model"]
    if model["type"] not in MODEL_ITEMS:
        raise ValueError("unknown material model %r" % model["type"])
    for source in (material, model):
        for name, value in source.items():
            if name in schema.PARAMETERS and name in fluid.bl_rna.properties:
                setattr(fluid, name, value)
    fluid.model = MODEL_ITEMS[model["type"]]


class VISCOSCOPE_OT_apply_effect(bpy.types.Operator):
    """Write the diagnosed model (the chosen effect's law and its fitted parameters) into the Fluid Material"""
    bl_idname = "viscoscope.apply_effect"
    bl_label = "Apply Effect"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        vs = context.scene.viscoscope
        return bool(vs.diagnosis_material) and not vs.diagnosis_applied

    def execute(self, context):
        vs = context.scene.viscoscope
        try:
            apply_material(vs.fluid, json.loads(vs.diagnosis_material))
        except (ValueError, KeyError, TypeError) as exc:
            self.report({'ERROR'}, "cannot apply the diagnosis: %s" % exc)
            return {'CANCELLED'}
        vs.fluid.identified_from = vs.diagnosis_source  # after η, whose edit clears it
        vs.diagnosis_applied = True
        self.report({'INFO'}, "%s applied to the Fluid Material" % vs.diagnosis_effect)
        return {'FINISHED'}


# diagnosis.json's suggested settings the panel can set: the property each goes into, how a value
# becomes the property's, and the button's words.
SUGGESTIONS = {
    "time_budget_s": ("diagnosis_budget_minutes", lambda s: math.ceil(s / 60.0), "Set Time Budget to %d min"),
    "resolution": ("identify_resolution", int, "Set Resolution to %d"),
    "grid_placements": ("grid_placements", int, "Set Grid Placements to %d"),
}


def suggestions(vs):
    """(setting, value, button text) for each suggested setting the panel holds a property of,
    within that property's range."""
    found = []
    for setting, value in json.loads(vs.diagnosis_suggested or "{}").items():
        if setting not in SUGGESTIONS:
            continue
        prop, convert, text = SUGGESTIONS[setting]
        rna = vs.bl_rna.properties[prop]
        value = convert(value)
        if rna.hard_min <= value <= rna.hard_max and value != getattr(vs, prop):
            found.append((setting, value, text % value))
    return found


class VISCOSCOPE_OT_use_suggestion(bpy.types.Operator):
    """Set the panel's setting to what the diagnosis suggests would tell (then run it again)"""
    bl_idname = "viscoscope.use_suggestion"
    bl_label = "Use Suggestion"
    bl_options = {'REGISTER', 'UNDO'}

    setting: bpy.props.StringProperty()

    def execute(self, context):
        vs = context.scene.viscoscope
        for setting, value, _text in suggestions(vs):
            if setting == self.setting:
                prop = SUGGESTIONS[setting][0]
                setattr(vs, prop, value)
                self.report({'INFO'}, "%s set to %s" % (vs.bl_rna.properties[prop].name, value))
                return {'FINISHED'}
        self.report({'ERROR'}, "the diagnosis suggests no %s the panel can set" % self.setting)
        return {'CANCELLED'}


class _DiagnoseBase(JobOperator):
    job_kind = "diagnose"
    run_name = "diagnosis"

    folder = staticmethod(diagnose_dir)

    def prepare(self, context):
        vs = context.scene.viscoscope
        if not vs.diagnosis_effects:
            raise engine.EngineError("no effect to try: choose at least one of the Diagnose panel's effects")
        self.time_budget_s = 60.0 * vs.diagnosis_budget_minutes
        # All of them: the engine leaves out, and lists in not_tried, those the scene cannot hold.
        chosen = [e["name"] for e in schema.EFFECTS if e["name"] in vs.diagnosis_effects]
        self.effects = None if len(chosen) == len(schema.EFFECTS) else chosen
        return super().prepare(context)

    def engine_args(self, exe, job, out_dir, threads):
        return engine.diagnose_args(exe, job, out_dir, threads, time_budget_s=self.time_budget_s, effects=self.effects)

    def on_success(self, context, out_dir):
        read_diagnosis(context, out_dir)


class VISCOSCOPE_OT_diagnose(_DiagnoseBase, bpy.types.Operator):
    """Find the effect the model lacks: fit the Newtonian model and each candidate effect to the first
    two thirds of the reference, predict the rest, and keep an effect only if it earns its parameters
    (runs in the background; Esc cancels)"""
    bl_idname = "viscoscope.diagnose"
    bl_label = "Diagnose"


class VISCOSCOPE_OT_diagnose_resume(_DiagnoseBase, bpy.types.Operator):
    """Continue a cancelled diagnosis: each model's fit resumes from its checkpoint"""
    bl_idname = "viscoscope.diagnose_resume"
    bl_label = "Resume"
    resume = True


classes = (VISCOSCOPE_OT_diagnose, VISCOSCOPE_OT_diagnose_resume, VISCOSCOPE_OT_apply_effect,
           VISCOSCOPE_OT_use_suggestion)

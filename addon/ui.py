"""The "Viscoscope" tab of the 3D Viewport sidebar. Panels only lay out properties and operators."""

import json
import textwrap

import bpy

from . import engine, mantaflow, prefs
from .operators import diagnose
from .operators import fluid as fluid_ops
from .operators import mantaflow_calibration as calibration
from .operators import runner
from .operators.silhouettes import made_with
from .presets import VISCOSCOPE_PT_fluid_presets


# Names of the panels drawn since the add-on was enabled (the Xvfb screenshot test reads it).
DRAWN = set()


class _ViscoscopePanel:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Viscoscope"

    def draw_header(self, _context):
        DRAWN.add(type(self).__name__)


# Width of a character of Blender's UI font at scale 1 (wide ones such as "%" and "m" count: labels
# that overrun are cut with "…"), and what a label's icon and the panel's margins take.
CHAR_PX, LABEL_MARGIN_PX = 7.5, 40
FALLBACK_CHARS = 25  # no region to measure (e.g. a popup): what the sidebar holds at its default width


def wrap_width(context):
    """Characters that fit on one label line across the region being drawn."""
    region = getattr(context, "region", None)
    if region is None or region.width <= 1:
        return FALLBACK_CHARS
    scale = context.preferences.system.ui_scale or 1.0  # 0 in background mode, where nothing is drawn
    return max(16, int((region.width - LABEL_MARGIN_PX * scale) / (CHAR_PX * scale)))


def draw_message(layout, context, text, icon='NONE', alert=False):
    """A long message as several labels, so the sidebar does not cut it off; the icon marks the first."""
    col = layout.column(align=True)
    col.alert = alert
    width = wrap_width(context)
    for paragraph in text.splitlines():
        for i, line in enumerate(textwrap.wrap(paragraph, width) or [""]):
            col.label(text=line, icon=icon if i == 0 or icon == 'NONE' else 'BLANK1')
    return col


def draw_labelled(layout, data, prop):
    """A path or object field under its own label: side by side, the sidebar cuts both short."""
    col = layout.column(align=True)
    col.label(text=data.bl_rna.properties[prop].name)
    col.prop(data, prop, text="")


def draw_job(layout, context, kind, run_op, run_text, resume_op=None):
    st = runner.status(context, kind)
    active = runner.is_running(kind)
    col = layout.column(align=True)
    if active:
        row = col.row(align=True)
        if hasattr(row, "progress"):  # Blender 4.0+
            row.progress(factor=st.progress / 100.0, text=st.status)
        else:
            row.prop(st, "progress", text=st.status, slider=True)
        row.operator("viscoscope.cancel_job", text="", icon='CANCEL').kind = kind
    else:
        row = col.row(align=True)
        row.scale_y = 1.4
        row.operator(run_op, text=run_text, icon='PLAY')
        if resume_op and st.can_resume:
            row.operator(resume_op, text="Resume", icon='RECOVER_LAST')
        if st.status:
            draw_message(col, context, st.status, icon='INFO')
    if st.note:
        draw_message(col, context, st.note, icon='INFO')
    if st.warning:
        draw_message(col, context, st.warning, icon='ERROR')
    if st.error and not active:
        draw_message(col, context, st.error, icon='ERROR', alert=True)


def draw_calibration(layout, context):
    """The Fluid Material panel's calibration: the button, its job, and the result."""
    vs = context.scene.viscoscope
    calibrate = calibration.VISCOSCOPE_OT_calibrate_mantaflow
    draw_job(layout, context, calibration.KIND, calibrate.bl_idname, calibrate.bl_label, resume_op=calibrate.bl_idname)
    if vs.fluid.model != 'NEWTONIAN':
        draw_message(layout, context, "Mantaflow has no shear-dependent viscosity: the calibration matches one "
                                      "constant viscosity to the footage", icon='ERROR')
    if not vs.mantaflow_calibration:
        return
    try:
        cal = json.loads(vs.mantaflow_calibration)
    except ValueError:
        return
    box = layout.box()
    draw_message(box, context, "Formula's viscosity_value: %.4g" % cal["formula_value"])
    draw_message(box, context, "Calibrated: %.4g, %.3g × the formula's (%s, resolution %d)" % (
        cal["chosen_value"], cal["ratio"], cal["domain"], cal["resolution"]), icon='CHECKMARK')
    col = box.column(align=True)
    for value, E in cal["values"]:
        col.label(text="%.4g: E %.4g" % (value, E), icon='RIGHTARROW' if value == cal["chosen_value"] else 'BLANK1')
    if cal.get("warning"):
        draw_message(box, context, cal["warning"].capitalize(), icon='ERROR')


REFERENCE_KINDS = {'CLIP': "clip", 'TRACK': "measured track", 'BOTH': "clip and track"}


def draw_runs(layout, context):
    """Other runs of this liquid: which scenes the job fits, and what each is compared with."""
    vs = context.scene.viscoscope
    col = layout.column(align=True)
    col.label(text="Other Runs of This Liquid")
    row = col.row()
    row.template_list("VISCOSCOPE_UL_runs", "", vs, "runs", vs, "runs_index", rows=2)
    buttons = row.column(align=True)
    buttons.operator("viscoscope.add_run", text="", icon='ADD')
    buttons.operator("viscoscope.remove_run", text="", icon='REMOVE')
    if vs.runs:
        names = ["%s (%s)" % (s.name, REFERENCE_KINDS[s.viscoscope.reference_kind])
                 for s in [context.scene] + [r.scene for r in vs.runs if r.scene is not None]]
        draw_message(col, context, "Identify and Diagnose fit %d runs sharing this Fluid Material: %s"
                     % (len(names), ", ".join(names)), icon='INFO')


class VISCOSCOPE_UL_runs(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active_data, _active_propname, _index):
        layout.prop(item, "scene", text="")


class VIEW3D_PT_viscoscope_reference(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Reference"

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        try:
            prefs.find_engine(context)
        except engine.EngineError as exc:
            # The sidebar is narrow: a short label here, the full reason in Preferences.
            row = layout.row()
            row.alert = True
            row.label(text="Engine not found" if "not found" in str(exc) else "Engine not usable", icon='ERROR')
            row.operator("preferences.addon_show", text="", icon='PREFERENCES').module = prefs.ADDON_ID
        layout.prop(vs, "reference_kind", text="")
        if vs.reference_kind in {'CLIP', 'BOTH'}:
            layout.operator("viscoscope.load_video", icon='FILE_MOVIE')
            if vs.clip:
                draw_message(layout, context, "%s · %d × %d px · %d frames · %.3g fps" % (
                    vs.clip.name, vs.clip.size[0], vs.clip.size[1], vs.clip.frame_duration, vs.clip.fps))
        if vs.reference_kind in {'TRACK', 'BOTH'}:
            draw_labelled(layout, vs, "track_csv")
            col = layout.column(align=True)
            col.prop(vs, "track_column")
            col.prop(vs, "track_observable", text="")
            col.prop(vs, "track_origin")
            if vs.track_observable == 'front':
                col.prop(vs, "track_direction")
            col.prop(vs, "track_band")
            if vs.reference_kind == 'BOTH':
                col.prop(vs, "track_weight")
        layout.prop(vs, "time_offset")
        draw_runs(layout, context)
        draw_labelled(layout, vs, "work_dir")


class VIEW3D_PT_viscoscope_camera(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Camera"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        draw_labelled(layout, vs, "camera")
        row = layout.row()
        row.template_list("VISCOSCOPE_UL_points", "", vs, "points", vs, "points_index", rows=3)
        col = row.column(align=True)
        col.operator("viscoscope.add_camera_point", text="", icon='ADD')
        col.operator("viscoscope.remove_camera_point", text="", icon='REMOVE')
        if 0 <= vs.points_index < len(vs.points):
            point = vs.points[vs.points_index]
            layout.column(align=True).prop(point, "world")
            layout.column(align=True).prop(point, "image")
        layout.operator("viscoscope.match_camera", icon='CON_CAMERASOLVER')
        if vs.reprojection_error >= 0.0:
            draw_message(layout, context, "Reprojection error: %.2f px" % vs.reprojection_error)
        layout.operator("viscoscope.export_camera", icon='EXPORT')


class VISCOSCOPE_UL_points(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active_data, _active_propname, _index):
        layout.prop(item, "label", text="", emboss=False)
        layout.label(text="(%.0f, %.0f)" % tuple(item.image))


class VIEW3D_PT_viscoscope_container(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Container"

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        layout.operator("viscoscope.add_cup", icon='MESH_CYLINDER')
        draw_labelled(layout, vs, "cup")
        if vs.cup is not None:
            cs = vs.cup.viscoscope
            col = layout.column(align=True)
            for attr in ("cup_inner_radius", "cup_height", "cup_wall", "cup_bottom", "cup_hole_radius"):
                col.prop(cs, attr)
        layout.prop(vs, "fill_volume")
        layout.prop(vs.fluid, "density")
        obj = context.active_object
        if obj is not None:
            box = layout.box()
            box.label(text=obj.name, icon='OBJECT_DATA')
            box.prop(obj.viscoscope, "role")
            if obj.viscoscope.role in {'CUP', 'SOLID'}:
                box.prop(obj.viscoscope, "transparent")
            if obj.viscoscope.role == 'EMITTER':
                col = box.column(align=True)
                for attr in ("emitter_radius", "emitter_flux", "emitter_start", "emitter_end"):
                    col.prop(obj.viscoscope, attr)


class VIEW3D_PT_viscoscope_silhouettes(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Silhouettes"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        col = layout.column(align=True)
        col.label(text="Background")
        col.prop(vs, "background", expand=True)
        if vs.background == 'PLATE_FRAME':
            col.prop(vs, "clean_plate_frame")
            draw_message(col, context, "Frame %d of the scene's timeline" % (context.scene.frame_start +
                                                                             vs.clean_plate_frame))
        elif vs.background == 'PLATE_IMAGE':
            col.prop(vs, "clean_plate_image", text="")
        else:
            col.prop(vs, "background_frames")
        col = layout.column(align=True)
        col.prop(vs, "var_threshold")
        col.prop(vs, "mask_threshold")
        col.prop(vs, "shadow_threshold")
        col.prop(vs, "edge_coverage")
        col.prop(vs, "close_diameter")
        col.prop(vs, "open_diameter")
        col.prop(vs, "min_blob")
        draw_job(layout, context, "extract", "viscoscope.preview_silhouettes", "Preview Silhouettes")
        if vs.preview_made_with and vs.preview_made_with != made_with(context.scene):
            draw_message(layout, context, "The masks shown were made from other settings or another clip: "
                                          "Preview again to see what Identify will use", icon='ERROR')


class VIEW3D_PT_viscoscope_identify(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Identify"

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        col = layout.column(align=True)
        col.prop(vs, "forward_model", text="")
        col.prop(vs, "eta_initial")
        col.prop(vs, "eta_spread")
        col.prop(vs, "identify_resolution")
        col.prop(vs, "max_generations")
        row = col.row()
        row.enabled = vs.forward_model != 'thin_film'  # the film has no grid to place
        row.prop(vs, "grid_placements")
        row = col.row()
        row.enabled = vs.grid_placements > 1 and vs.forward_model != 'thin_film'
        row.prop(vs, "placement_schedule", text="")
        col.prop(vs, "time_budget_minutes")
        draw_job(layout, context, "identify", "viscoscope.identify", "Identify Viscosity",
                 resume_op="viscoscope.identify_resume")


class VIEW3D_PT_viscoscope_results(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Results"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        if vs.result_eta > 0.0:
            draw_message(layout, context, "η = %.4g Pa·s, interval %.4g–%.4g Pa·s" % (
                vs.result_eta, vs.result_eta_low, vs.result_eta_high))
            for doubt in vs.result_doubts.splitlines():
                draw_message(layout, context, doubt, icon='ERROR', alert=True)
            if not vs.result_applied:
                draw_message(layout, context, "Not applied to the Fluid Material")
                layout.operator("viscoscope.apply_result", icon='CHECKMARK')
        else:
            layout.label(text="No identification yet")
        for name in ("convergence.png", "landscape.png"):
            img = bpy.data.images.get(name)
            if img is not None and img.preview is not None:
                layout.label(text=name[:-4].capitalize())
                layout.template_icon(icon_value=img.preview.icon_id, scale=8.0)
        layout.operator("viscoscope.load_fields", icon='VOLUME_DATA')


class VIEW3D_PT_viscoscope_diagnose(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Diagnose"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        draw_message(layout, context, "Fits the Identify panel's job and each effect chosen below: one "
                                      "identification each, sharing the time budget")
        layout.prop(vs, "diagnosis_effects")
        layout.prop(vs, "diagnosis_budget_minutes")
        draw_job(layout, context, "diagnose", "viscoscope.diagnose", "Diagnose",
                 resume_op="viscoscope.diagnose_resume")
        if not vs.diagnosis_conclusion:
            return
        box = layout.box()
        icon = {'missing_effect': 'VIEWZOOM', 'no_missing_effect': 'CHECKMARK'}.get(vs.diagnosis_verdict, 'ERROR')
        draw_message(box, context, vs.diagnosis_conclusion[:1].upper() + vs.diagnosis_conclusion[1:], icon=icon)
        for setting, _value, text in diagnose.suggestions(vs):
            box.operator("viscoscope.use_suggestion", text=text, icon='MODIFIER').setting = setting
        draw_message(box, context, vs.diagnosis_grid)
        for line in vs.diagnosis_report.splitlines():
            draw_message(box, context, line)
        if vs.diagnosis_material:
            if vs.diagnosis_applied:
                draw_message(box, context, "Applied to the Fluid Material", icon='CHECKMARK')
            else:
                box.operator("viscoscope.apply_effect", icon='CHECKMARK')
        img = bpy.data.images.get("diagnosis.png")
        if img is not None and img.preview is not None:
            layout.label(text="Residual over time, before and after")
            layout.template_icon(icon_value=img.preview.icon_id, scale=8.0)


class VIEW3D_PT_viscoscope_fluid(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Fluid Material"

    def draw_header_preset(self, _context):
        VISCOSCOPE_PT_fluid_presets.draw_panel_header(self.layout)

    def draw(self, context):
        layout = self.layout
        fluid = context.scene.viscoscope.fluid
        draw_labelled(layout, fluid, "description")
        col = layout.column(align=True)
        col.prop(fluid, "viscosity")
        if fluid.identified_from:
            draw_message(col, context, "Identified from " + fluid.identified_from, icon='INFO')
        col.prop(fluid, "density")
        col.prop(fluid, "surface_tension")
        col.prop(fluid, "slip_length")
        layout.prop(fluid, "model")
        if fluid.model != 'NEWTONIAN':
            col = layout.column(align=True)
            if fluid.model in ('POWER_LAW', 'HERSCHEL_BULKLEY'):
                col.prop(fluid, "consistency")
            col.prop(fluid, "flow_index")
            if fluid.model == 'CARREAU':
                col.prop(fluid, "eta_infinity")
                col.prop(fluid, "relaxation_time")
            if fluid.model == 'HERSCHEL_BULKLEY':
                col.prop(fluid, "yield_stress")
        col = layout.column(align=True)
        col.prop(fluid, "color")
        col.prop(fluid, "roughness")
        col.prop(fluid, "transmission")
        layout.operator("viscoscope.apply_to_domain", icon='MOD_FLUIDSIM')
        if fluid.model != 'NEWTONIAN':
            domain = context.active_object
            if domain is not None and mantaflow.SHEAR_VISCOSITY_KEY in domain:
                text = "Mantaflow has " + fluid_ops.describe_stand_in(
                    (domain[mantaflow.SHEAR_RATE_KEY], domain[mantaflow.SHEAR_VISCOSITY_KEY]))
            else:
                text = ("Mantaflow's viscosity is constant: Apply sets η at the domain's typical shear "
                        "rate √(g/L), by the engine's law")
            draw_message(layout, context, text, icon='INFO')
        draw_calibration(layout, context)


class VIEW3D_PT_viscoscope_transfer(_ViscoscopePanel, bpy.types.Panel):
    bl_label = "Transfer"

    def draw(self, context):
        layout = self.layout
        vs = context.scene.viscoscope
        col = layout.column(align=True)
        col.prop(vs, "sim_resolution")
        col.prop(vs, "sim_frames")
        col.prop(vs, "sim_seed")
        layout.operator("viscoscope.export_scene", icon='EXPORT')
        draw_job(layout, context, "simulate", "viscoscope.simulate", "Simulate with Viscoscope")


classes = (
    VISCOSCOPE_UL_points,
    VISCOSCOPE_UL_runs,
    VIEW3D_PT_viscoscope_reference,
    VIEW3D_PT_viscoscope_camera,
    VIEW3D_PT_viscoscope_container,
    VIEW3D_PT_viscoscope_silhouettes,
    VIEW3D_PT_viscoscope_identify,
    VIEW3D_PT_viscoscope_results,
    VIEW3D_PT_viscoscope_diagnose,
    VIEW3D_PT_viscoscope_fluid,
    VIEW3D_PT_viscoscope_transfer,
)

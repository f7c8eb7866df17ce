"""Fluid material: apply it to a Mantaflow domain."""

import os

import bpy

from .. import engine, mantaflow, prefs, scene_export, units


def material_name(fluid):
    return "Viscoscope " + (fluid.description.strip().splitlines()[0][:40] if fluid.description.strip() else "Fluid")


def mantaflow_stand_in(context, domain):
    """(γ̇, η at γ̇): the constant viscosity Mantaflow gets for a shear-dependent Fluid Material on
    this domain, by the engine's law at the scene's typical shear rate; None for a Newtonian one."""
    scene = context.scene
    fluid = scene.viscoscope.fluid
    if fluid.model == 'NEWTONIAN':
        return None
    gravity = scene.gravity.length if scene.use_gravity else 9.81
    rate = mantaflow.typical_shear_rate(domain, scene.unit_settings.scale_length, gravity)
    path = os.path.join(scene_export.work_dir(scene), "material.json")
    scene_export.export_material(fluid, bpy.path.abspath(path))
    return rate, engine.apparent_viscosity(prefs.find_engine(context), bpy.path.abspath(path), rate)


def describe_stand_in(stand_in):
    return "η %.4g Pa·s at the typical shear rate √(g/L) = %.3g /s (Mantaflow's viscosity is constant)" % (
        stand_in[1], stand_in[0])


class VISCOSCOPE_OT_apply_to_domain(bpy.types.Operator):
    """Set the active Mantaflow liquid domain's viscosity (ν = η/ρ, both diffusion and variational paths), surface tension and material"""
    bl_idname = "viscoscope.apply_to_domain"
    bl_label = "Apply to Mantaflow Domain"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return mantaflow.fluid_modifier(context.active_object) is not None

    def execute(self, context):
        fluid = context.scene.viscoscope.fluid
        obj = context.active_object
        try:
            stand_in = mantaflow_stand_in(context, obj)
            material = mantaflow.fluid_material(fluid, material_name(fluid))
            info = mantaflow.apply_fluid(obj, fluid, context.scene.unit_settings.scale_length, material, stand_in)
        except (mantaflow.DomainError, units.UnitError, engine.EngineError, scene_export.ExportError, OSError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        msg = "ν = %.4g m²/s → base %.3g, exponent %d, viscosity_value %.4g" % (
            info["nu"], info["viscosity_base"], info["viscosity_exponent"], info["viscosity_value"])
        if stand_in is not None:
            msg = describe_stand_in(stand_in) + ": " + msg
        if info["clamped"]:
            self.report({'WARNING'}, msg + " (clamped to 10: domain too small for this viscosity)")
        else:
            self.report({'INFO'}, msg)
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_apply_to_domain,)

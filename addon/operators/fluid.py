"""Fluid material: apply it to a Mantaflow domain."""

import bpy

from .. import mantaflow, units


def material_name(fluid):
    return "Viscoscope " + (fluid.description.strip().splitlines()[0][:40] if fluid.description.strip() else "Fluid")


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
            material = mantaflow.fluid_material(fluid, material_name(fluid))
            info = mantaflow.apply_fluid(obj, fluid, context.scene.unit_settings.scale_length, material)
        except (mantaflow.DomainError, units.UnitError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        msg = "ν = %.4g m²/s → base %.3g, exponent %d, viscosity_value %.4g" % (
            info["nu"], info["viscosity_base"], info["viscosity_exponent"], info["viscosity_value"])
        if info["clamped"]:
            self.report({'WARNING'}, msg + " (clamped to 10: domain too small for this viscosity)")
        else:
            self.report({'INFO'}, msg)
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_apply_to_domain,)

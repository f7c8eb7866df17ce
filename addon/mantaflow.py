"""Apply a Viscoscope fluid material to Blender's own Mantaflow liquid domain.

Both of Mantaflow's viscosity paths are set (DESIGN.md, "What Mantaflow does"):
- diffusion: use_diffusion, viscosity_base · 10^-viscosity_exponent = ν (Blender's preset convention);
- variational: use_viscosity, viscosity_value = ν · T / L², T Mantaflow's time unit
  (units.MANTAFLOW_TIME_UNIT_S), L the domain's longest side in metres.
The variational value depends on the domain size, so it is recomputed when the domain is resized.
Mantaflow's viscosity is one constant: a shear-dependent material is applied at the viscosity the
engine's law gives at the scene's typical shear rate (typical_shear_rate), which the panel shows.
Every assignment to a domain setting frees the domain's Mantaflow cache, baked frames included, even
when the value does not change; settings are therefore only assigned when what is stored would change.
"""

import array
import math

import bpy
from bpy.app.handlers import persistent

from . import units

NU_KEY = "viscoscope_nu"  # kinematic viscosity last applied to a domain, m²/s
# A shear-dependent material's stand-in last applied to a domain: the shear rate (1/s) and η (Pa·s).
SHEAR_RATE_KEY, SHEAR_VISCOSITY_KEY = "viscoscope_shear_rate", "viscoscope_viscosity_at_shear_rate"
VISCOSITY_VALUE_MAX = 10.0  # RNA hard max of viscosity_value


class DomainError(ValueError):
    pass


def fluid_modifier(obj):
    if obj is None:
        return None
    for mod in obj.modifiers:
        if mod.type == 'FLUID':
            return mod
    return None


def domain_settings(obj):
    mod = fluid_modifier(obj)
    if mod is None or mod.fluid_type != 'DOMAIN':
        raise DomainError("'%s' is not a Mantaflow fluid domain" % (obj.name if obj else "nothing"))
    if mod.domain_settings.domain_type != 'LIQUID':
        raise DomainError("'%s' is a gas domain; viscosity applies to liquid domains" % obj.name)
    return mod.domain_settings


def longest_side_m(obj, scale_length):
    """The domain's longest side in metres, from its original mesh: obj.dimensions is the evaluated
    geometry, which for a baked domain is the liquid surface, not the domain box."""
    verts = obj.data.vertices
    if not verts:
        raise DomainError("domain '%s' has no vertices" % obj.name)
    scale = obj.matrix_world.to_scale()
    sides = []
    for axis in range(3):
        coords = [v.co[axis] for v in verts]
        sides.append((max(coords) - min(coords)) * abs(scale[axis]))
    return max(sides) * scale_length


def typical_shear_rate(obj, scale_length, gravity):
    """√(g/L), L the domain's longest side (m): the rate at which liquid falling or slumping across
    the scene shears (8 /s over 15 cm), where a shear-dependent material's constant stand-in is taken."""
    return math.sqrt(max(gravity, 1e-9) / longest_side_m(obj, scale_length))


def set_domain_setting(ds, name, value):
    """Assign ds.<name> only if what Blender stores would change; returns whether it did.

    RNA float properties are single precision, so a double is compared after rounding it to a float:
    compared as doubles they would always differ, and each assignment frees the cache.
    """
    current = getattr(ds, name)
    stored = array.array('f', [value])[0] if isinstance(current, float) else value
    if current == stored:
        return False
    setattr(ds, name, value)
    return True


def variational_value(obj, nu, scale_length):
    """(viscosity_value for ν in this domain, the same clamped to what Mantaflow accepts)."""
    value = units.variational_viscosity_value(nu, longest_side_m(obj, scale_length))
    return value, min(value, VISCOSITY_VALUE_MAX)


def apply_variational(obj, ds, nu, scale_length):
    value, clamped = variational_value(obj, nu, scale_length)
    set_domain_setting(ds, "use_viscosity", True)
    set_domain_setting(ds, "viscosity_value", clamped)
    return value, clamped


def apply_fluid(obj, fluid, scale_length, material=None, shear_rate_viscosity=None):
    """Set the domain's viscosity, surface tension and material from a ViscoscopeFluid; for a
    shear-dependent one, shear_rate_viscosity = (γ̇, η at γ̇) is the viscosity Mantaflow gets.

    Returns a dict of what was set (and whether viscosity_value had to be clamped).
    """
    ds = domain_settings(obj)
    eta = fluid.viscosity
    for key in (SHEAR_RATE_KEY, SHEAR_VISCOSITY_KEY):
        if key in obj:
            del obj[key]
    if shear_rate_viscosity is not None:
        obj[SHEAR_RATE_KEY], obj[SHEAR_VISCOSITY_KEY] = shear_rate_viscosity
        eta = shear_rate_viscosity[1]
    nu = units.kinematic_viscosity(eta, fluid.density)
    base, exponent = units.diffusion_base_exponent(nu)
    # Re-applying the same fluid keeps a bake; a different one frees it, as editing the domain does.
    set_domain_setting(ds, "use_diffusion", True)
    set_domain_setting(ds, "viscosity_base", base)
    set_domain_setting(ds, "viscosity_exponent", exponent)
    set_domain_setting(ds, "surface_tension",
                       units.check_finite("surface tension", fluid.surface_tension, minimum=0.0))
    value, clamped = apply_variational(obj, ds, nu, scale_length)
    obj[NU_KEY] = nu
    if material is not None:
        if obj.data.materials:
            obj.data.materials[0] = material
        else:
            obj.data.materials.append(material)
    return {"nu": nu, "viscosity_base": base, "viscosity_exponent": exponent,
            "viscosity_value": clamped, "clamped": value != clamped}


def fluid_material(fluid, name):
    """A Principled BSDF material for the fluid (created or updated)."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = next((n for n in mat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED'), None)
    if bsdf is None:
        bsdf = mat.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
    colour = tuple(fluid.color) + (1.0,)
    bsdf.inputs["Base Color"].default_value = colour
    bsdf.inputs["Roughness"].default_value = fluid.roughness
    for socket_name in ("Transmission", "Transmission Weight"):  # 3.x / 4.x names
        if socket_name in bsdf.inputs:
            bsdf.inputs[socket_name].default_value = fluid.transmission
            break
    mat.diffuse_color = colour
    mat["viscoscope_viscosity"] = fluid.viscosity
    mat["viscoscope_density"] = fluid.density
    return mat


@persistent
def _recompute_on_resize(scene, depsgraph):
    """Keep viscosity_value consistent with ν when a domain is resized.

    Runs after every depsgraph update, the one that follows a bake included, so it must not assign an
    unchanged value: that would free the bake just made."""
    scale_length = scene.unit_settings.scale_length
    for update in depsgraph.updates:
        if not (update.is_updated_transform or update.is_updated_geometry):
            continue
        obj = getattr(update.id, "original", None)
        if not isinstance(obj, bpy.types.Object) or NU_KEY not in obj:
            continue
        mod = fluid_modifier(obj)
        if mod is None or mod.fluid_type != 'DOMAIN':
            continue
        try:
            _, clamped = variational_value(obj, obj[NU_KEY], scale_length)
        except (units.UnitError, DomainError):
            continue
        set_domain_setting(mod.domain_settings, "viscosity_value", clamped)


def register():
    if _recompute_on_resize not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_recompute_on_resize)


def unregister():
    if _recompute_on_resize in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_recompute_on_resize)

"""Container: the parametric cup with a bottom hole, the ground plane and the domain around them."""

import bpy

from .. import cup_mesh


def _link(context, obj):
    context.collection.objects.link(obj)
    return obj


def add_cup(context, location=(0.0, 0.0, 0.0), inner_radius=None, depth=None, wall=None, bottom=None,
            hole_radius=None, stand_height=None):
    """Create the cup (role CUP), a ground plane (role GROUND) and a domain box (role DOMAIN).

    Lengths are in Blender units; None keeps the property defaults (a 43 mm-radius cup, metres).
    The cup stands on legs of stand_height above the ground so the liquid can run out of the hole.
    """
    scene = context.scene
    k = 1.0 / scene.unit_settings.scale_length  # the defaults are in metres
    mesh = bpy.data.meshes.new("Viscoscope Cup")
    cup = _link(context, bpy.data.objects.new("Viscoscope Cup", mesh))
    cs = cup.viscoscope
    cs.role = 'CUP'
    # Set every parameter before the first rebuild (each assignment triggers one).
    for attr, value in (("cup_inner_radius", inner_radius), ("cup_height", depth), ("cup_wall", wall),
                        ("cup_bottom", bottom), ("cup_hole_radius", hole_radius)):
        default = cs.bl_rna.properties[attr].default * k
        setattr(cs, attr, default if value is None else value)
    cup_mesh.build_cup_mesh(mesh, cs)
    stand = (0.05 * k) if stand_height is None else stand_height
    cup.location = (location[0], location[1], location[2] + stand)

    ground_mesh = bpy.data.meshes.new("Viscoscope Ground")
    half = 0.2 * k
    ground_mesh.from_pydata([(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)], [],
                            [(0, 1, 2, 3)])
    ground = _link(context, bpy.data.objects.new("Viscoscope Ground", ground_mesh))
    ground.location = location
    ground.viscoscope.role = 'GROUND'

    domain = add_domain(context, (location[0] - 0.12 * k, location[1] - 0.12 * k, location[2]),
                        (location[0] + 0.12 * k, location[1] + 0.12 * k,
                         location[2] + stand + cs.cup_bottom + cs.cup_height + 0.01 * k))
    scene.viscoscope.cup = cup
    return cup, ground, domain


def add_domain(context, lo, hi, name="Viscoscope Domain"):
    """A box object spanning [lo, hi] (Blender units) with role DOMAIN, drawn as bounds."""
    sx, sy, sz = ((h - l) / 2.0 for l, h in zip(lo, hi))
    verts = [(x, y, z) for z in (-sz, sz) for y in (-sy, sy) for x in (-sx, sx)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    domain = _link(context, bpy.data.objects.new(name, mesh))
    domain.location = tuple((l + h) / 2.0 for l, h in zip(lo, hi))
    domain.display_type = 'BOUNDS'
    domain.hide_render = True
    domain.viscoscope.role = 'DOMAIN'
    return domain


class VISCOSCOPE_OT_add_cup(bpy.types.Operator):
    """Add a parametric cup with a hole in its bottom, a ground plane and a simulation domain"""
    bl_idname = "viscoscope.add_cup"
    bl_label = "Add Cup"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        if context.mode != 'OBJECT':
            self.report({'ERROR'}, "Add Cup works in Object Mode")
            return {'CANCELLED'}
        cup, _ground, _domain = add_cup(context, tuple(context.scene.cursor.location))
        for obj in context.view_layer.objects:
            obj.select_set(False)
        cup.select_set(True)
        context.view_layer.objects.active = cup
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_add_cup,)

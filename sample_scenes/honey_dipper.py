"""Transfer scene: honey running onto a honey dipper held over a bowl (Mantaflow, preset applied).

    blender -b --factory-startup --python sample_scenes/honey_dipper.py -- --out DIR \
        [--res 32] [--frames 20] [--samples 8] [--no-bake] [--no-render]
writes DIR/honey_dipper.blend, its Mantaflow cache DIR/honey_dipper_cache and DIR/honey_dipper.png
(one small Cycles frame).
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

HONEY = ("Honey (sample values: Takahashi & Lin 2019 measured 7.86 Pa·s)", 7.86, 1420.0, 0.07, (0.92, 0.56, 0.07))


def dipper(scene, material):
    """A wooden dipper lying along X: a handle and a head of stacked rings, in metres."""
    import bpy
    parts = []
    bpy.ops.mesh.primitive_cylinder_add(radius=0.004, depth=0.12, location=(-0.05, 0, 0.05),
                                        rotation=(0, math.pi / 2, 0))
    parts.append(bpy.context.active_object)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.008, depth=0.05, location=(0.03, 0, 0.05),
                                        rotation=(0, math.pi / 2, 0))
    parts.append(bpy.context.active_object)
    for i in range(5):
        ring = _common.torus(scene, "Ring", 0.011, 0.0035, (0.01 + 0.01 * i, 0, 0.05), material, 32, 12)
        ring.rotation_euler = (0, math.pi / 2, 0)
        parts.append(ring)
    for p in parts:
        p.select_set(True)
        if p.data.materials:
            p.data.materials[0] = material
        else:
            p.data.materials.append(material)
    bpy.context.view_layer.objects.active = parts[0]
    bpy.ops.object.join()
    obj = bpy.context.active_object
    obj.name = "Honey Dipper"
    return obj


def build(res=32, frames=20, cache_dir=None):
    import bpy
    scene = _common.empty_scene()
    _common.set_fluid(scene, *HONEY)
    wood = _common.simple_material("Wood", (0.55, 0.33, 0.15), 0.6)
    ceramic = _common.simple_material("Bowl", (0.2, 0.3, 0.45), 0.3)
    stick = dipper(scene, wood)
    bowl = _common.torus(scene, "Bowl Rim", 0.05, 0.005, (0.03, 0, 0.0), ceramic, sides=8)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.05, depth=0.004, location=(0.03, 0, -0.002))
    bowl_floor = bpy.context.active_object
    bowl_floor.name = "Bowl"
    bowl_floor.data.materials.append(ceramic)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.008, location=(0.03, 0, 0.085))
    source = bpy.context.active_object
    source.name = "Honey Inflow"
    source.hide_render = True
    _common.make_flow(source, velocity=(0.0, 0.0, -0.2))
    for obj in (stick, bowl, bowl_floor):
        _common.make_effector(obj)
    dom = _common.make_domain(scene, (-0.03, -0.05, -0.004), (0.09, 0.05, 0.1), res, frames, cache_dir=cache_dir)
    _common.apply_preset_to_domain(dom)
    _common.add_camera(scene, (0.1, -0.17, 0.12), (0.03, 0.0, 0.04), lens=45)
    _common.add_lights(scene, (0.03, 0, 0.04), scale=0.3)
    return scene, dom


if __name__ == "__main__":
    args = _common.parse_args(default_res=32, default_frames=20)
    scene, dom = build(args.res, args.frames, os.path.join(args.out, "honey_dipper_cache"))
    if not args.no_bake:
        _common.bake(dom)
    if not args.no_render:
        _common.render(scene, os.path.join(args.out, "honey_dipper.png"), args.samples, frame=args.frames)
    _common.save(os.path.join(args.out, "honey_dipper.blend"))

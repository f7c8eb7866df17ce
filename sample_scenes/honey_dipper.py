"""Transfer scene: honey running onto a honey dipper held over a bowl.

    blender -b --factory-startup --python sample_scenes/honey_dipper.py -- --out DIR \
        [--fluid honey|creamed_honey | --preset FILE] [--solver mantaflow|viscoscope] \
        [--res 32] [--frames 20] [--samples 8] [--no-bake] [--no-render]
writes DIR/honey_dipper_<fluid>.blend, one small Cycles frame DIR/honey_dipper_<fluid>.png and either
Mantaflow's cache DIR/honey_dipper_<fluid>_cache (the fluid applied to its domain) or the Viscoscope
engine's run in DIR/honey_dipper_<fluid>_viscoscope (the whole material simulated: a shear-thinning
honey runs off the dipper sooner than a Newtonian one of its low-shear viscosity).
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

# Sample materials; replace them with your identified presets (--preset).
FLUIDS = {
    "honey": {"description": "Honey (sample values: Takahashi & Lin 2019 measured 7.86 Pa·s)", "viscosity": 7.86,
              "density": 1420.0, "surface_tension": 0.07, "color": (0.92, 0.56, 0.07)},
    # Creamed honey thins under shear: a power law with the Newtonian honey's viscosity at 1/s.
    "creamed_honey": {"description": "Creamed honey (sample values: a shear-thinning liquid)", "model": 'POWER_LAW',
                      "viscosity": 7.86, "consistency": 7.86, "flow_index": 0.4, "density": 1420.0,
                      "surface_tension": 0.07, "color": (0.95, 0.78, 0.45)},
}
POUR_SPEED = 0.2     # m/s out of the inflow
POUR_SECONDS = 1.0   # how long the Viscoscope emitter pours (Mantaflow's inflow pours all along)


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


def build(fluid, solver="mantaflow", res=32, frames=20, cache_dir=None):
    """The scene with `fluid` (fluid property → value, or a preset file's path) in its Fluid Material."""
    scene = _common.empty_scene()
    _common.use_fluid(scene, fluid)
    wood = _common.simple_material("Wood", (0.55, 0.33, 0.15), 0.6)
    ceramic = _common.simple_material("Bowl", (0.2, 0.3, 0.45), 0.3)
    stick = dipper(scene, wood)
    bowl = _common.torus(scene, "Bowl Rim", 0.05, 0.005, (0.03, 0, 0.0), ceramic, sides=8)
    bowl_floor = _common.cylinder(scene, "Bowl", 0.05, 0.004, (0.03, 0, -0.002))
    bowl_floor.data.materials.append(ceramic)
    source = _common.cylinder(scene, "Honey Inflow", 0.008, 0.016, (0.03, 0, 0.085))
    _common.transfer_source(source, solver, POUR_SPEED, POUR_SECONDS)
    for obj in (stick, bowl, bowl_floor):
        _common.transfer_solid(obj, solver)
    dom = _common.transfer_domain(scene, (-0.03, -0.05, -0.004), (0.09, 0.05, 0.1), res, frames, solver,
                                  cache_dir=cache_dir)
    if solver == "mantaflow":
        _common.apply_preset_to_domain(dom)
    _common.add_camera(scene, (0.1, -0.17, 0.12), (0.03, 0.0, 0.04), lens=45)
    _common.add_lights(scene, (0.03, 0, 0.04), scale=0.3)
    return scene, dom


if __name__ == "__main__":
    args = _common.parse_args(fluids=FLUIDS)
    name = "honey_dipper_" + _common.run_name(args)
    scene, dom = build(args.preset or FLUIDS[args.fluid], args.solver, args.res, args.frames,
                       os.path.join(args.out, name + "_cache"))
    _common.finish(scene, dom, args, name)

"""Transfer scene: a donut glazed with syrup poured from above (Mantaflow, the preset applied).

    blender -b --factory-startup --python sample_scenes/donut_syrup.py -- --out DIR \
        [--fluid chocolate|caramel|honey] [--res 32] [--frames 20] [--samples 8] [--no-bake] [--no-render]
writes DIR/donut_<fluid>.blend, its Mantaflow cache DIR/donut_<fluid>_cache and DIR/donut_<fluid>.png
(one small Cycles frame).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

# Sample materials (η Pa·s, ρ kg/m³, σ N/m, colour); replace with your identified presets.
FLUIDS = {
    "chocolate": ("Chocolate syrup (sample values)", 10.0, 1300.0, 0.05, (0.12, 0.04, 0.015)),
    "caramel": ("Caramel (sample values)", 50.0, 1400.0, 0.06, (0.75, 0.38, 0.08)),
    "honey": ("Honey (sample values)", 8.0, 1420.0, 0.07, (0.9, 0.55, 0.08)),
}


def build(fluid_key="chocolate", res=32, frames=20, cache_dir=None):
    import bpy
    scene = _common.empty_scene()
    _common.set_fluid(scene, *FLUIDS[fluid_key])
    dough = _common.simple_material("Dough", (0.78, 0.5, 0.25), 0.6)
    plate_mat = _common.simple_material("Plate", (0.9, 0.9, 0.88), 0.2)
    # A 9 cm donut on a plate, in metres.
    donut = _common.torus(scene, "Donut", 0.03, 0.015, (0, 0, 0.017), dough)
    plate = _common.torus(scene, "Plate", 0.07, 0.004, (0, 0, 0.0), plate_mat, sides=8)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.012, depth=0.02, location=(0.028, 0.0, 0.09))
    source = bpy.context.active_object
    source.name = "Syrup Inflow"
    source.hide_render = True
    _common.make_flow(source, velocity=(0.0, 0.0, -0.3))
    for obj in (donut, plate):
        _common.make_effector(obj)
    dom = _common.make_domain(scene, (-0.075, -0.075, -0.005), (0.075, 0.075, 0.105), res, frames,
                              cache_dir=cache_dir)
    _common.apply_preset_to_domain(dom)
    _common.add_camera(scene, (0.0, -0.2, 0.14), (0.0, 0.0, 0.02), lens=45)
    _common.add_lights(scene, (0, 0, 0.02), scale=0.3)
    return scene, dom


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    fluid = "chocolate"
    if "--fluid" in argv:
        i = argv.index("--fluid")
        fluid = argv[i + 1]
        del argv[i:i + 2]
        sys.argv = sys.argv[:sys.argv.index("--") + 1] + argv
    if fluid not in FLUIDS:
        raise SystemExit("error: --fluid must be one of %s" % ", ".join(FLUIDS))
    args = _common.parse_args()
    scene, dom = build(fluid, args.res, args.frames, os.path.join(args.out, "donut_%s_cache" % fluid))
    if not args.no_bake:
        _common.bake(dom)
    if not args.no_render:
        _common.render(scene, os.path.join(args.out, "donut_%s.png" % fluid), args.samples, frame=args.frames)
    _common.save(os.path.join(args.out, "donut_%s.blend" % fluid))

"""Transfer scene: a donut glazed with syrup poured from above.

    blender -b --factory-startup --python sample_scenes/donut_syrup.py -- --out DIR \
        [--fluid chocolate|caramel|honey|glaze | --preset FILE] [--solver mantaflow|viscoscope] \
        [--res 32] [--frames 20] [--samples 8] [--no-bake] [--no-render]
writes DIR/donut_<fluid>.blend, one small Cycles frame DIR/donut_<fluid>.png and either Mantaflow's
cache DIR/donut_<fluid>_cache (the fluid applied to its domain) or the Viscoscope engine's run in
DIR/donut_<fluid>_viscoscope (the whole material simulated: the glaze's yield stress holds it on the
donut, where a Newtonian syrup runs down to the plate). --preset names the result after the file.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

# Sample materials; replace them with your identified presets (--preset).
FLUIDS = {
    "chocolate": {"description": "Chocolate syrup (sample values)", "viscosity": 10.0, "density": 1300.0,
                  "surface_tension": 0.05, "color": (0.12, 0.04, 0.015)},
    "caramel": {"description": "Caramel (sample values)", "viscosity": 50.0, "density": 1400.0,
                "surface_tension": 0.06, "color": (0.75, 0.38, 0.08)},
    "honey": {"description": "Honey (sample values)", "viscosity": 8.0, "density": 1420.0,
              "surface_tension": 0.07, "color": (0.9, 0.55, 0.08)},
    # A sugar glaze that sets: a Herschel–Bulkley liquid whose yield stress holds a layer
    # τ_y/(ρg) ≈ 6 mm thick on the donut's sides.
    "glaze": {"description": "Sugar glaze (sample values: a yield-stress liquid)", "model": 'HERSCHEL_BULKLEY',
              "viscosity": 10.0, "consistency": 5.0, "flow_index": 0.6, "yield_stress": 80.0,
              "density": 1350.0, "surface_tension": 0.06, "color": (0.92, 0.88, 0.82)},
}
POUR_SPEED = 0.3     # m/s out of the inflow
POUR_SECONDS = 1.0   # how long the Viscoscope emitter pours (Mantaflow's inflow pours all along)


def build(fluid, solver="mantaflow", res=32, frames=20, cache_dir=None):
    """The scene with `fluid` (fluid property → value, or a preset file's path) in its Fluid Material."""
    scene = _common.empty_scene()
    _common.use_fluid(scene, fluid)
    dough = _common.simple_material("Dough", (0.78, 0.5, 0.25), 0.6)
    plate_mat = _common.simple_material("Plate", (0.9, 0.9, 0.88), 0.2)
    # A 9 cm donut on a plate, in metres.
    donut = _common.torus(scene, "Donut", 0.03, 0.015, (0, 0, 0.017), dough)
    plate = _common.torus(scene, "Plate", 0.07, 0.004, (0, 0, 0.0), plate_mat, sides=8)
    source = _common.cylinder(scene, "Syrup Inflow", 0.008, 0.02, (0.028, 0.0, 0.09))
    _common.transfer_source(source, solver, POUR_SPEED, POUR_SECONDS)
    for obj in (donut, plate):
        _common.transfer_solid(obj, solver)
    dom = _common.transfer_domain(scene, (-0.075, -0.075, -0.005), (0.075, 0.075, 0.105), res, frames, solver,
                                  cache_dir=cache_dir)
    if solver == "mantaflow":
        _common.apply_preset_to_domain(dom)
    _common.add_camera(scene, (0.0, -0.2, 0.14), (0.0, 0.0, 0.02), lens=45)
    _common.add_lights(scene, (0, 0, 0.02), scale=0.3)
    return scene, dom


if __name__ == "__main__":
    args = _common.parse_args(fluids=FLUIDS)
    name = "donut_" + _common.run_name(args)
    scene, dom = build(args.preset or FLUIDS[args.fluid], args.solver, args.res, args.frames,
                       os.path.join(args.out, name + "_cache"))
    _common.finish(scene, dom, args, name)

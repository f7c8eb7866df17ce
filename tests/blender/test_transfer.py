"""A fluid preset carries its whole material into a Viscoscope Transfer simulation: saved, loaded into
a fresh scene and simulated by the engine through the Transfer panel, a yield-stress preset's column
of liquid comes to rest near the arrest radius of theory, where a Newtonian preset of the same
consistency keeps spreading; the engine's record of the run holds the preset's law and values. The
sample transfer scenes (donut, honey dipper) show the same with a user's presets: the glaze's yield
stress stops it on the donut where a stiffer Newtonian syrup still runs, and a shear-thinning honey runs
off the dipper sooner than a Newtonian honey of its low-shear viscosity."""

import json
import math
import os
import struct
import subprocess
import sys

import bpy
import pytest

import conftest
from viscoscope import presets
from viscoscope.operators.simulate import transfer_dir

sys.path.insert(0, os.path.join(conftest.REPO, "sample_scenes"))
import donut_syrup  # noqa: E402
import honey_dipper  # noqa: E402

pytestmark = pytest.mark.engine

CELLS = 40          # across the 0.2 m domain: 5 mm cells
FPS, FRAMES = 10, 30
COLUMN = 0.04       # m, a cube of liquid standing on the ground
KETCHUP = {"description": "Yield-stress test liquid", "model": 'HERSCHEL_BULKLEY', "viscosity": 2.0,
           "density": 1000.0, "surface_tension": 0.0, "consistency": 2.0, "flow_index": 1.0, "yield_stress": 60.0}
SYRUP = {"description": "Newtonian test liquid", "model": 'NEWTONIAN', "viscosity": 2.0, "density": 1000.0,
         "surface_tension": 0.0}


def _slump_scene(scene):
    def add(name, role, corners=None):
        data = None
        if corners is not None:
            data = bpy.data.meshes.new(name)
            data.from_pydata([(x, y, z) for x in corners[0] for y in corners[1] for z in corners[2]], [], [])
        obj = bpy.data.objects.new(name, data)
        scene.collection.objects.link(obj)
        obj.viscoscope.role = role
        return obj
    add("Domain", 'DOMAIN', ((-0.1, 0.1), (-0.1, 0.1), (0.0, 0.05)))
    add("Ground", 'GROUND')
    half = COLUMN / 2
    add("Column", 'LIQUID', ((-half, half), (-half, half), (0.0, COLUMN)))
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_start = 1
    vs = scene.viscoscope
    vs.sim_resolution, vs.sim_frames, vs.cup = CELLS, FRAMES, None


def _save_preset(fluid, name, values):
    """The fluid set to `values` and saved as a preset, as the panel's header does; the file's path."""
    for key, value in values.items():
        setattr(fluid, key, value)
    folder = presets.user_preset_dir()
    before = set(os.listdir(folder)) if os.path.isdir(folder) else set()
    assert bpy.ops.viscoscope.fluid_preset_add(name=name) == {'FINISHED'}
    (new,) = set(os.listdir(folder)) - before
    return os.path.join(folder, new)


def _spread(mesh_obj, scene, frame):
    """The liquid's largest horizontal distance from the column's axis at a frame, from the surface
    mesh the Transfer panel imports (Volume to Mesh of the engine's level set)."""
    scene.frame_set(frame)
    evaluated = mesh_obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        assert len(mesh.vertices) > 0, "no surface at frame %d" % frame
        return max(math.hypot(v.co.x, v.co.y) for v in mesh.vertices)
    finally:
        evaluated.to_mesh_clear()


def _simulate_with_preset(ctx, preset_path, run):
    ctx.scene.viscoscope.work_dir = run
    ctx.scene.viscoscope.fluid.model = 'NEWTONIAN'  # whatever the panel held: the preset sets it
    assert bpy.ops.viscoscope.fluid_preset_load(filepath=preset_path) == {'FINISHED'}
    assert bpy.ops.viscoscope.simulate('EXEC_DEFAULT') == {'FINISHED'}, ctx.scene.viscoscope.simulate_job.error
    out_dir = os.path.join(transfer_dir(ctx.scene), "out")
    record = json.load(open(os.path.join(out_dir, "simulation.json")))
    mesh_obj = next(o for o in ctx.scene.objects if o.name.startswith("Viscoscope Liquid") and o.type == 'MESH')
    start = ctx.scene.frame_start
    spread = [_spread(mesh_obj, ctx.scene, start + f) for f in (FRAMES // 3, FRAMES)]
    for obj in [o for o in ctx.scene.objects if o.name.startswith("Viscoscope Liquid")]:
        bpy.data.objects.remove(obj)
    return record["scene"]["material"], spread


def test_a_yield_stress_preset_rests_where_a_newtonian_one_spreads(ctx, tmp_work, engine_path, use_engine):
    use_engine(engine_path)
    _slump_scene(ctx.scene)
    fluid = ctx.scene.viscoscope.fluid
    ketchup = _save_preset(fluid, "Transfer Test Ketchup", KETCHUP)
    syrup = _save_preset(fluid, "Transfer Test Syrup", SYRUP)
    cell = 0.2 / CELLS

    material, (ketchup_early, ketchup_end) = _simulate_with_preset(ctx, ketchup, str(tmp_work / "ketchup"))
    assert material["model"]["type"] == "herschel_bulkley"
    for key in ("yield_stress", "consistency", "flow_index"):
        assert material["model"][key] == pytest.approx(KETCHUP[key], rel=1e-6), key
    material, (syrup_early, syrup_end) = _simulate_with_preset(ctx, syrup, str(tmp_work / "syrup"))
    assert material["model"]["type"] == "newtonian" and material["viscosity"] == pytest.approx(2.0)

    # Roussel & Coussot 2005: a Bingham slump of volume V rests at R = (15V/8π)^{2/5} (ρg/2τ_y)^{1/5}
    # (thin-layer theory; this puddle is about half as high as wide).
    arrest = (15 * COLUMN ** 3 / (8 * math.pi)) ** 0.4 * (KETCHUP["density"] * 9.81 / (2 * KETCHUP["yield_stress"])) ** 0.2
    print("\n[transfer] spread from the axis at %.1f s and %.1f s: yield stress %.1f → %.1f mm (arrest radius "
          "%.1f mm), Newtonian %.1f → %.1f mm (cells %.0f mm)" % (
              FRAMES / 3 / FPS, FRAMES / FPS, 1e3 * ketchup_early, 1e3 * ketchup_end, 1e3 * arrest,
              1e3 * syrup_early, 1e3 * syrup_end, 1e3 * cell))
    # The yield stress stops the slump near the arrest radius: over the last two seconds it moves by
    # less than half a cell. The Newtonian liquid goes on spreading, as t^{1/8}: 15 % over them.
    assert abs(ketchup_end - ketchup_early) < 0.5 * cell
    assert ketchup_end == pytest.approx(arrest, rel=0.15)
    assert syrup_end - syrup_early > cell
    assert syrup_end > ketchup_end + cell


# The sample scenes on the engine: 40 cells along the domain's longest side (3–4 mm), 1.5 s at 24 fps.
SAMPLE_RES, SAMPLE_FRAMES = 40, 36


def _particles(path):
    """Positions and speeds (m, m/s) of a particles_fffff.bin (docs/formats.md)."""
    with open(path, "rb") as fh:
        data = fh.read()
    assert data[:4] == b"VSCP"
    (count,) = struct.unpack_from("<Q", data, 8)
    values = struct.unpack_from("<%df" % (6 * count), data, 16)
    rows = [values[6 * i:6 * i + 6] for i in range(count)]
    return [r[:3] for r in rows], [math.sqrt(r[3] ** 2 + r[4] ** 2 + r[5] ** 2) for r in rows]


def _sample_scene_with_preset(script, preset_path, out, engine_path):
    """Run a sample transfer scene as a user would, with a preset file on the Viscoscope engine; the
    material the engine simulated and the liquid's particles at the last frame."""
    scene_name = {"donut_syrup.py": "donut", "honey_dipper.py": "honey_dipper"}[script]
    env = dict(os.environ, VISCOSCOPE_ENGINE=engine_path)
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                           os.path.join(conftest.REPO, "sample_scenes", script), "--", "--out", str(out),
                           "--preset", preset_path, "--solver", "viscoscope", "--res", str(SAMPLE_RES),
                           "--frames", str(SAMPLE_FRAMES), "--no-render"],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    name = scene_name + "_" + os.path.splitext(os.path.basename(preset_path))[0]
    out_dir = os.path.join(str(out), name + "_viscoscope", "transfer", "out")
    assert os.path.isfile(os.path.join(str(out), name + ".blend"))
    record = json.load(open(os.path.join(out_dir, "simulation.json")))
    return record["scene"]["material"], _particles(os.path.join(out_dir, "particles_%05d.bin" % SAMPLE_FRAMES))


def _median(values):
    values = sorted(values)
    return values[len(values) // 2]


def test_the_sample_scenes_carry_a_yield_stress_and_a_shear_thinning_preset(ctx, tmp_path, engine_path):
    def save(name, values):  # the sample's fluid on a fresh panel's: Newtonian unless it says otherwise
        return _save_preset(ctx.scene.viscoscope.fluid, name, dict({"model": 'NEWTONIAN'}, **values))
    glaze = save("Transfer Test Glaze", donut_syrup.FLUIDS["glaze"])
    syrup = save("Transfer Test Chocolate", donut_syrup.FLUIDS["chocolate"])
    creamed = save("Transfer Test Creamed Honey", honey_dipper.FLUIDS["creamed_honey"])
    honey = save("Transfer Test Honey", honey_dipper.FLUIDS["honey"])

    material, (_, glaze_speed) = _sample_scene_with_preset("donut_syrup.py", glaze, tmp_path, engine_path)
    assert material["model"]["type"] == "herschel_bulkley"
    assert material["model"]["yield_stress"] == pytest.approx(donut_syrup.FLUIDS["glaze"]["yield_stress"])
    material, (_, syrup_speed) = _sample_scene_with_preset("donut_syrup.py", syrup, tmp_path, engine_path)
    assert material["model"]["type"] == "newtonian"
    material, (creamed_at, _) = _sample_scene_with_preset("honey_dipper.py", creamed, tmp_path, engine_path)
    assert material["model"]["type"] == "power_law"
    assert material["model"]["flow_index"] == pytest.approx(honey_dipper.FLUIDS["creamed_honey"]["flow_index"])
    material, (honey_at, _) = _sample_scene_with_preset("honey_dipper.py", honey, tmp_path, engine_path)
    assert material["model"]["type"] == "newtonian"

    # The dipper's head hangs 35.5 mm above the bowl's floor at its lowest: below 30 mm the honey has left it.
    def left_the_dipper(positions):
        return sum(p[2] < 0.03 for p in positions) / len(positions)
    glaze_still = sorted(glaze_speed)[int(0.9 * len(glaze_speed))]
    print("\n[transfer] donut at %.1f s: glaze's 90th-percentile speed %.2f mm/s, Newtonian syrup's median "
          "%.1f mm/s; honey dipper: %.0f %% of the shear-thinning honey has left it, %.0f %% of the Newtonian" % (
              SAMPLE_FRAMES / 24, 1e3 * glaze_still, 1e3 * _median(syrup_speed),
              100 * left_the_dipper(creamed_at), 100 * left_the_dipper(honey_at)))
    # The glaze's yield stress holds every layer thinner than τ_y/(ρg) ≈ 6 mm: by the end 90 % of it
    # creeps slower than 1 mm/s, while the Newtonian syrup, twice its consistency, still runs at a
    # cell (3.75 mm) per second or more.
    cell = 0.15 / SAMPLE_RES
    assert glaze_still < 1e-3
    assert _median(syrup_speed) > cell
    # Draining off the dipper shears the honey faster than 1/s, where the power law is thinner than
    # its consistency (the Newtonian honey's η): more of it has run into the bowl.
    assert left_the_dipper(creamed_at) > left_the_dipper(honey_at) + 0.2

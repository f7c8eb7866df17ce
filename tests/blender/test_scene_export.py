"""Scene export: Blender → scene JSON in SI units under a non-1 unit scale; one-line errors."""

import json
import math
import os
import subprocess
import time

import bpy
import pytest

from viscoscope import scene_export
from viscoscope.operators import container

CM = 0.01  # scale_length: one Blender unit is one centimetre


def _cup_scene(ctx, scale_length):
    ctx.scene.unit_settings.scale_length = scale_length
    k = 1.0 / scale_length  # metres → Blender units
    cup, ground, domain = container.add_cup(ctx, (1.0 * k * 0.1, 0.0, 0.0), inner_radius=0.043 * k,
                                           depth=0.06 * k, wall=0.003 * k, bottom=0.004 * k,
                                           hole_radius=0.009 * k, stand_height=0.05 * k)
    ctx.scene.viscoscope.fill_volume = 1.7e-4 * k ** 3
    fluid = ctx.scene.viscoscope.fluid
    fluid.viscosity, fluid.density, fluid.surface_tension = 8.0, 1400.0, 0.07
    return cup, ground, domain


@pytest.mark.parametrize("scale_length", [1.0, CM, 2.5])
def test_cup_scene_round_trip_in_si(ctx, tmp_work, scale_length):
    cup, _ground, domain = _cup_scene(ctx, scale_length)
    path = os.path.join(str(tmp_work), "scene.json")
    scene_export.export_scene(ctx.scene, path)
    with open(path) as fh:
        data = json.load(fh)
    assert data["format"] == "viscoscope.scene" and data["version"] == 1
    solids = {s["type"]: s for s in data["solids"]}
    c = solids["cup"]
    assert c["inner_radius"] == pytest.approx(0.043)
    assert c["height"] == pytest.approx(0.06)
    assert c["wall_thickness"] == pytest.approx(0.003)
    assert c["bottom_thickness"] == pytest.approx(0.004)
    assert c["hole_radius"] == pytest.approx(0.009)
    assert c["position"] == pytest.approx([0.1, 0.0, 0.05])
    assert solids["ground"]["height"] == pytest.approx(0.0)
    fill = [l for l in data["liquids"] if l["type"] == "cup_fill"][0]
    assert fill["volume"] == pytest.approx(1.7e-4)
    assert data["solids"][fill["cup"]]["type"] == "cup"
    d = data["domain"]
    assert d["min"] == pytest.approx([0.1 - 0.12, -0.12, 0.0])
    assert d["max"] == pytest.approx([0.1 + 0.12, 0.12, 0.05 + 0.004 + 0.06 + 0.01])
    assert data["material"] == {"density": 1400.0, "viscosity": 8.0, "surface_tension": pytest.approx(0.07),
                                "slip_length": 0.0, "model": {"type": "newtonian"}}
    assert data["gravity"] == pytest.approx([0.0, 0.0, -9.81])
    assert data["fps"] == 24 and data["frames"] == 60


def test_mesh_solid_box_liquid_and_emitter(ctx, tmp_work):
    ctx.scene.unit_settings.scale_length = CM
    container.add_domain(ctx, (-10, -10, 0), (10, 10, 20))
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0, 0, 1))  # 2 cm cube at z 0..2 cm
    solid = ctx.active_object
    solid.viscoscope.role = 'SOLID'
    solid.name = "Viscoscope weird/name \"x\""
    bpy.ops.mesh.primitive_cube_add(size=4.0, location=(0, 0, 10))
    liquid = ctx.active_object
    liquid.name = "Viscoscope liquid"
    liquid.viscoscope.role = 'LIQUID'
    bpy.ops.object.empty_add(location=(0, 0, 15), rotation=(math.pi, 0, 0))
    emitter = ctx.active_object
    emitter.name = "Viscoscope emitter"
    emitter.viscoscope.role = 'EMITTER'
    emitter.viscoscope.emitter_radius = 0.5     # 5 mm
    emitter.viscoscope.emitter_flux = 2.0       # 2 cm³/s
    data = scene_export.export_scene(ctx.scene, os.path.join(str(tmp_work), "s", "scene.json"))
    mesh = [s for s in data["solids"] if s["type"] == "mesh"][0]
    obj_path = os.path.join(str(tmp_work), "s", mesh["path"])
    assert os.path.isfile(obj_path) and "/" not in mesh["path"] and '"' not in mesh["path"]
    zs = [float(l.split()[3]) for l in open(obj_path) if l.startswith("v ")]
    assert min(zs) == pytest.approx(0.0, abs=1e-9) and max(zs) == pytest.approx(0.02)
    assert sum(1 for l in open(obj_path) if l.startswith("f ")) == 12
    box = [l for l in data["liquids"] if l["type"] == "box"][0]
    assert box["min"] == pytest.approx([-0.02, -0.02, 0.08]) and box["max"] == pytest.approx([0.02, 0.02, 0.12])
    em = [l for l in data["liquids"] if l["type"] == "emitter"][0]
    assert em["center"] == pytest.approx([0, 0, 0.15])
    assert em["normal"] == pytest.approx([0, 0, -1], abs=1e-6)
    assert em["radius"] == pytest.approx(0.005)
    assert em["flux"] == pytest.approx(2e-6)
    assert data["domain"]["max"] == pytest.approx([0.1, 0.1, 0.2])


@pytest.mark.parametrize("field, value, message", [
    ("viscosity", float("nan"), "material viscosity must be a finite number"),
    ("density", float("nan"), "material density must be a finite number"),
    ("surface_tension", float("nan"), "material surface_tension must be a finite number"),
])
def test_bad_material_values_give_one_line_errors(ctx, tmp_work, field, value, message):
    _cup_scene(ctx, 1.0)
    # RNA clamps negatives and infinities; NaN still arrives from scripts and drivers.
    setattr(ctx.scene.viscoscope.fluid, field, value)
    with pytest.raises(scene_export.ExportError) as err:
        scene_export.build_scene(ctx.scene, str(tmp_work))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_missing_domain_and_missing_liquid(ctx, tmp_work):
    with pytest.raises(scene_export.ExportError, match="exactly one object with Viscoscope role 'Domain'"):
        scene_export.build_scene(ctx.scene, str(tmp_work))
    container.add_domain(ctx, (0, 0, 0), (1, 1, 1))
    with pytest.raises(scene_export.ExportError, match="no liquid"):
        scene_export.build_scene(ctx.scene, str(tmp_work))


def test_hole_larger_than_cup_and_tilted_cup(ctx, tmp_work):
    cup, _g, _d = _cup_scene(ctx, 1.0)
    cup.viscoscope.cup_hole_radius = 0.05
    with pytest.raises(scene_export.ExportError, match="hole_radius .* must be smaller"):
        scene_export.build_scene(ctx.scene, str(tmp_work))
    cup.viscoscope.cup_hole_radius = 0.009
    cup.rotation_euler = (0.3, 0, 0)
    ctx.view_layer.update()
    with pytest.raises(scene_export.ExportError, match="must stand upright"):
        scene_export.build_scene(ctx.scene, str(tmp_work))


def test_cup_mesh_has_a_hole_and_follows_parameters(ctx):
    cup, _g, _d = _cup_scene(ctx, 1.0)
    zs_at_axis = [v.co.z for v in cup.data.vertices if math.hypot(v.co.x, v.co.y) < 1e-9]
    assert zs_at_axis == []  # a hole: no vertex on the axis
    radii = [math.hypot(v.co.x, v.co.y) for v in cup.data.vertices]
    assert min(radii) == pytest.approx(0.009) and max(radii) == pytest.approx(0.046)
    cup.viscoscope.cup_hole_radius = 0.0
    assert any(math.hypot(v.co.x, v.co.y) < 1e-9 for v in cup.data.vertices)
    assert max(v.co.z for v in cup.data.vertices) == pytest.approx(0.064)


def test_camera_json(ctx, tmp_work):
    ctx.scene.unit_settings.scale_length = CM
    bpy.ops.object.camera_add(location=(0, -50, 10), rotation=(math.radians(80), 0, 0))
    cam = ctx.active_object
    cam.name = "Viscoscope cam"
    cam.scale = (3, 3, 3)
    cam.data.lens = 35
    data = scene_export.export_camera(cam, ctx.scene, os.path.join(str(tmp_work), "cam.json"))
    assert data["format"] == "viscoscope.blender_camera" and data["lens_mm"] == 35
    m = data["matrix_world"]
    assert [m[0][3], m[1][3], m[2][3]] == pytest.approx([0, -0.5, 0.1])
    for j in range(3):
        assert math.sqrt(sum(m[i][j] ** 2 for i in range(3))) == pytest.approx(1.0)
    assert m[3] == [0, 0, 0, 1]


def _simulated_scene(engine_path, scene_path, out_dir):
    """The scene as the engine read it: `simulate` records it in DIR/simulation.json."""
    proc = subprocess.run([engine_path, "simulate", scene_path, "--out", out_dir, "--progress", "none"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    with open(os.path.join(out_dir, "simulation.json")) as fh:
        return json.load(fh)["scene"]


@pytest.mark.engine
def test_transparent_container_round_trips_through_the_engine(ctx, tmp_work, engine_path):
    """"Transparent (glass)" on the container becomes its solid's "transparent" key, which the engine reads."""
    cup, _ground, _domain = _cup_scene(ctx, 1.0)
    vs = ctx.scene.viscoscope
    vs.sim_resolution, vs.sim_frames = 8, 1
    assert cup.viscoscope.transparent is False  # opaque unless the artist says otherwise
    for transparent in (True, False):
        cup.viscoscope.transparent = transparent
        path = os.path.join(str(tmp_work), "glass_%s" % transparent, "scene.json")
        data = scene_export.export_scene(ctx.scene, path)
        index = next(i for i, s in enumerate(data["solids"]) if s["type"] == "cup")
        assert data["solids"][index]["transparent"] is transparent
        read = _simulated_scene(engine_path, path, os.path.join(os.path.dirname(path), "sim"))
        assert read["solids"][index].get("transparent") is transparent, read["solids"][index]


def _engine_warnings(engine_path, scene_path, timeout=120):
    """The warnings `simulate` gives before its first frame (then it is stopped)."""
    from viscoscope import engine
    job = engine.EngineJob([engine_path, "simulate", scene_path, "--out", scene_path + ".sim",
                            "--progress", "json"]).start()
    warnings, deadline = [], time.monotonic() + timeout
    while not job.finished:
        events = job.poll()
        warnings += [e["message"] for e in events if e.get("event") == "warning"]
        if any(e.get("event") == "progress" for e in events):
            break
        assert time.monotonic() < deadline
        time.sleep(0.05)
    job.kill()
    job.wait(30)
    return warnings + [e["message"] for e in job.poll() if e.get("event") == "warning"]


@pytest.mark.engine
def test_identify_resolution_meets_the_engines_need_for_the_cup(ctx, tmp_work, engine_path):
    """The job's grid is fine enough for the sample cup's hole by the engine's own measure (no warning),
    one cell coarser is not, and the panel is told when the add-on raised it."""
    from viscoscope.operators import identify
    _cup_scene(ctx, 1.0)
    vs = ctx.scene.viscoscope
    data = scene_export.build_scene(ctx.scene, str(tmp_work))
    resolution, note = identify.identify_resolution(ctx.scene, [data])
    assert resolution > vs.identify_resolution and str(resolution) in note
    for res, warned in ((resolution, False), (resolution - 1, True)):
        vs.sim_resolution = res
        path = os.path.join(str(tmp_work), "res_%d.json" % res)
        scene_export.export_scene(ctx.scene, path)
        warnings = _engine_warnings(engine_path, path)
        assert any("hole" in w for w in warnings) is warned, (res, warnings)
    vs.identify_resolution = resolution + 4  # a finer grid than needed is kept as asked
    assert identify.identify_resolution(ctx.scene, [data]) == (resolution + 4, "")


def _files(folder):
    return {path.name: path.read_bytes() for path in folder.iterdir()}


@pytest.mark.parametrize("failing", ["scene.json", "solid_Box.obj"])
def test_a_failed_write_leaves_the_previous_export_and_names_the_file(ctx, tmp_work, failing):
    """A disk that fills up while a file is written (/dev/full behind its .partial answers ENOSPC): the
    previous export stands byte for byte, nothing half-written is left, and one line names the file."""
    _cup_scene(ctx, 1.0)
    bpy.ops.mesh.primitive_cube_add(size=0.02, location=(0.08, 0.0, 0.01))
    ctx.active_object.name = "Box"
    ctx.active_object.viscoscope.role = 'SOLID'
    folder = tmp_work / "export"
    scene_path = folder / "scene.json"
    assert bpy.ops.viscoscope.export_scene(filepath=str(scene_path)) == {'FINISHED'}
    previous = _files(folder)
    assert set(previous) == {"scene.json", "solid_Box.obj"}

    ctx.scene.viscoscope.fluid.viscosity = 3.0
    ctx.active_object.location.x = 0.09
    (folder / (failing + ".partial")).symlink_to("/dev/full")
    with pytest.raises(RuntimeError) as raised:
        bpy.ops.viscoscope.export_scene(filepath=str(scene_path))
    message = str(raised.value).strip()
    assert "cannot write %s: No space left on device" % (folder / failing) in message and "\n" not in message
    assert _files(folder)[failing] == previous[failing]
    assert not [name for name in os.listdir(folder) if name.endswith(".partial")]


def test_a_nan_in_the_camera_is_refused_and_the_previous_camera_file_stands(ctx, tmp_work):
    """A NaN from a script or driver used to stop json.dump halfway through the file, with a traceback."""
    bpy.ops.object.camera_add(location=(0, -0.5, 0.1), rotation=(math.radians(80), 0, 0))
    ctx.scene.viscoscope.camera = ctx.active_object
    path = tmp_work / "blender_camera.json"
    assert bpy.ops.viscoscope.export_camera() == {'FINISHED'}
    previous = path.read_bytes()
    ctx.active_object.data.shift_x = float("nan")
    with pytest.raises(RuntimeError) as raised:
        bpy.ops.viscoscope.export_camera()
    message = str(raised.value).strip()
    assert "camera shift_x must be a finite number" in message and "\n" not in message
    assert path.read_bytes() == previous and os.listdir(tmp_work) == ["blender_camera.json"]

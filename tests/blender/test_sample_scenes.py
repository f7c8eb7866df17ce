"""The sample transfer scenes build headless, bake at low resolution and render one small frame."""

import collections
import json
import os
import re
import subprocess
import textwrap

import bpy
import pytest

import conftest

pytestmark = pytest.mark.slow

FRAMES = 8
FAST = ["--res", "20", "--frames", str(FRAMES), "--samples", "2"]
# Caramel's ν makes Mantaflow's diffusion path (use_diffusion, set by Apply) blow up on these grids: the
# liquid is thrown across the domain. Its placement check is expected to fail until that is fixed.
SCATTERED_BY_DIFFUSION = {"caramel"}


def _run(script, out, *extra):
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                           os.path.join(conftest.REPO, "sample_scenes", script), "--", "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def _not_blank(path):
    img = bpy.data.images.load(path)
    try:
        px = img.pixels[:]
        lum = [px[i] + px[i + 1] + px[i + 2] for i in range(0, len(px), 4 * 13)]
        return max(lum) - min(lum) > 0.2
    finally:
        bpy.data.images.remove(img)


def _check_background_shows(path):
    """The scenes have no ground: around the objects the frame shows the world's flat grey. A domain
    evaluated as its box (no bake) covers the whole frame in noisy liquid material instead."""
    img = bpy.data.images.load(path)
    try:
        px = img.pixels[:]
    finally:
        bpy.data.images.remove(img)
    colours = collections.Counter(tuple(round(c * 50) for c in px[i:i + 3]) for i in range(0, len(px), 4))
    colour, count = colours.most_common(1)[0]
    share = count / (len(px) // 4)
    assert max(colour) - min(colour) <= 2 and share > 1 / 3, "most common colour %s/50 in %.0f%% of the frame" % (
        colour, 100 * share)


def _check_cache(cache_dir):
    """Mantaflow wrote data and mesh files for every baked frame (named <name>_<frame>.<ext>)."""
    for kind in ("data", "mesh"):
        folder = os.path.join(cache_dir, kind)
        names = os.listdir(folder) if os.path.isdir(folder) else []
        per_frame = collections.Counter(int(m.group(1)) for m in map(re.compile(r"_(\d+)\.").search, names) if m)
        assert all(per_frame[frame] > 0 for frame in range(1, FRAMES + 1)), "%s: files per frame %s" % (
            kind, dict(per_frame))


# Opens the saved .blend with the add-on enabled, as a user would, and reports world-space bounding
# boxes at the last frame: the evaluated domain (the liquid surface read from the cache) and objects.
_LIQUID_PROBE = """
import json, sys, bpy, mathutils
sys.path.insert(0, %r)
import _common
_common.enable_addon()
def box(points):
    points = list(points)
    if not points:
        return None
    return [[min(p[i] for p in points) for i in range(3)], [max(p[i] for p in points) for i in range(3)]]
scene = bpy.context.scene
scene.frame_set(scene.frame_end)
dom = bpy.data.objects["Fluid Domain"]
evaluated = dom.evaluated_get(bpy.context.evaluated_depsgraph_get())
mesh = evaluated.to_mesh()
report = {"liquid": box(evaluated.matrix_world @ v.co for v in mesh.vertices),
          "domain": box(dom.matrix_world @ v.co for v in dom.data.vertices),
          "objects": {o.name: box(o.matrix_world @ mathutils.Vector(c) for c in o.bound_box)
                      for o in scene.objects if o.type == 'MESH' and o is not dom}}
evaluated.to_mesh_clear()
print("LIQUID " + json.dumps(report))
"""


def _liquid_at_last_frame(blend):
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", blend, "--python-exit-code", "1",
                           "--python-expr", _LIQUID_PROBE % os.path.join(conftest.REPO, "sample_scenes")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    line = next(l for l in proc.stdout.splitlines() if l.startswith("LIQUID "))
    return json.loads(line[len("LIQUID "):])


def _check_liquid(report, inflow, onto):
    """At the last frame the liquid is a stream from the inflow down onto `onto`, not the domain box."""
    assert report["liquid"] is not None, "the domain evaluates to no liquid at all"
    lo, hi = report["liquid"]
    dom_lo, dom_hi = report["domain"]
    for axis in (0, 1):
        assert hi[axis] - lo[axis] < 0.5 * (dom_hi[axis] - dom_lo[axis]), (
            "liquid %s spans most of the domain %s" % (report["liquid"], report["domain"]))
    in_lo, in_hi = report["objects"][inflow]
    for axis in (0, 1):
        assert lo[axis] < (in_lo[axis] + in_hi[axis]) / 2 < hi[axis], "liquid %s is not under %s %s" % (
            report["liquid"], inflow, report["objects"][inflow])
    on_lo, on_hi = report["objects"][onto]
    assert all(lo[i] < on_hi[i] and hi[i] > on_lo[i] for i in range(3)), "liquid %s has not reached %s %s" % (
        report["liquid"], onto, report["objects"][onto])


def _check_domain(blend, eta, rho):
    with bpy.data.libraries.load(blend) as (src, dst):
        dst.objects = ["Fluid Domain"]
        dst.scenes = list(src.scenes)
    dom = dst.objects[0]
    try:
        ds = next(m for m in dom.modifiers if m.type == 'FLUID').domain_settings
        nu = eta / rho
        assert ds.use_diffusion and ds.use_viscosity
        assert ds.viscosity_base * 10.0 ** -ds.viscosity_exponent == pytest.approx(nu, rel=1e-6)
        assert ds.viscosity_value == pytest.approx(nu * 0.4 / max(dom.dimensions) ** 2, rel=1e-5)
        assert dom.active_material is not None and dom.active_material.name.startswith("Viscoscope")
    finally:
        for scene in dst.scenes:
            bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(dom)


@pytest.mark.parametrize("fluid, eta, rho", [("chocolate", 10.0, 1300.0), ("caramel", 50.0, 1400.0),
                                              ("honey", 8.0, 1420.0)])
def test_donut_scene(tmp_path, fluid, eta, rho):
    _run("donut_syrup.py", tmp_path, "--fluid", fluid, *FAST)
    name = "donut_%s" % fluid
    _check_cache(str(tmp_path / (name + "_cache")))
    assert _not_blank(str(tmp_path / (name + ".png")))
    _check_background_shows(str(tmp_path / (name + ".png")))
    _check_domain(str(tmp_path / (name + ".blend")), eta, rho)
    report = _liquid_at_last_frame(str(tmp_path / (name + ".blend")))
    if fluid in SCATTERED_BY_DIFFUSION:
        with pytest.raises(AssertionError):  # passes once fixed: then drop it from SCATTERED_BY_DIFFUSION
            _check_liquid(report, "Syrup Inflow", "Donut")
        pytest.xfail("Mantaflow's diffusion path scatters %s: liquid %s" % (fluid, report["liquid"]))
    _check_liquid(report, "Syrup Inflow", "Donut")


def test_honey_dipper_scene(tmp_path):
    _run("honey_dipper.py", tmp_path, *FAST)
    _check_cache(str(tmp_path / "honey_dipper_honey_cache"))
    assert _not_blank(str(tmp_path / "honey_dipper_honey.png"))
    _check_background_shows(str(tmp_path / "honey_dipper_honey.png"))
    _check_domain(str(tmp_path / "honey_dipper_honey.blend"), 7.86, 1420.0)
    _check_liquid(_liquid_at_last_frame(str(tmp_path / "honey_dipper_honey.blend")), "Honey Inflow", "Honey Dipper")


# Inside Blender on a built capture.blend: move the camera away, Match Camera from the sample's
# points with the engine ($VISCOSCOPE_ENGINE), print where it went.
MATCH_SCRIPT = textwrap.dedent('''
    import json, os, sys
    import bpy
    sys.path.insert(0, os.path.join(%r, "sample_scenes"))
    import _common
    _common.enable_addon()
    scene = bpy.context.scene
    vs, cam = scene.viscoscope, scene.viscoscope.camera
    truth = list(cam.matrix_world.translation)
    size = list(vs.clip.size) if vs.clip else [scene.render.resolution_x, scene.render.resolution_y]
    cam.location = (0.05, -0.6, 0.2)
    vs.work_dir = sys.argv[sys.argv.index("--") + 1]
    result = bpy.ops.viscoscope.match_camera()
    print("MATCH " + json.dumps({"result": sorted(result), "truth": truth, "size": size,
                                 "matched": list(cam.matrix_world.translation), "error": vs.reprojection_error,
                                 "points": [list(p.image) for p in vs.points]}))
''') % conftest.REPO


def _match_sample_camera(blend, work):
    os.makedirs(str(work), exist_ok=True)
    script = os.path.join(str(work), "match.py")
    with open(script, "w") as fh:
        fh.write(MATCH_SCRIPT)
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", str(blend),
                           "--python", script, "--", str(work)], capture_output=True, text=True, timeout=300)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("MATCH ")), None)
    assert line, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(line[len("MATCH "):])


def _assert_points_pose_the_camera(match):
    """The sample's points lie in its clip's image and Match Camera puts the camera back within 2 mm."""
    w, h = match["size"]
    for u, v in match["points"]:
        assert -0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5, (u, v, w, h)
    assert match["result"] == ["FINISHED"], match
    assert all(abs(a - b) < 0.002 for a, b in zip(match["matched"], match["truth"])), match
    assert 0.0 <= match["error"] < 0.1


@pytest.mark.engine
def test_capture_scene_points_match_its_camera(addon, tmp_path, engine_path):
    _run("capture_scene.py", tmp_path)
    _assert_points_pose_the_camera(_match_sample_camera(tmp_path / "capture.blend", tmp_path / "work"))


def test_capture_scene(addon, tmp_path):
    _run("capture_scene.py", tmp_path)
    with bpy.data.libraries.load(str(tmp_path / "capture.blend")) as (src, dst):
        dst.scenes = list(src.scenes)
    scene = dst.scenes[0]
    try:
        vs = scene.viscoscope
        assert vs.cup is not None and vs.cup.viscoscope.role == 'CUP'
        assert vs.camera is not None and len(vs.points) == 4
        assert vs.fluid.viscosity == pytest.approx(8.0)
    finally:
        bpy.data.scenes.remove(scene)


@pytest.mark.engine
def test_capture_scene_with_reference_clip(addon, tmp_path, engine_path):
    """--clip: the engine simulates the pour, Cycles renders it, the clip becomes the reference."""
    _run("capture_scene.py", tmp_path, "--clip", "--samples", "1")
    clip = tmp_path / "reference.mp4"
    assert clip.is_file()
    with bpy.data.libraries.load(str(tmp_path / "capture.blend")) as (src, dst):
        dst.scenes = list(src.scenes)
    scene = dst.scenes[0]
    try:
        vs = scene.viscoscope
        assert vs.clip is not None and os.path.samefile(bpy.path.abspath(vs.clip.filepath), str(clip))
        assert vs.clip.frame_duration == vs.sim_frames + 1
        assert "Viscoscope Liquid" not in bpy.data.objects
        # The clip is not made on the grid and seed that Identify and Transfer use.
        simulated = json.load(open(tmp_path / "reference_sim" / "transfer" / "scene.json"))
        assert simulated["domain"]["resolution"] == round(vs.identify_resolution * 4 / 3) != vs.identify_resolution
        assert simulated["seed"] == vs.sim_seed + 1
        assert (vs.sim_resolution, vs.sim_seed) == (32, 1)
        cam = scene.camera.data
        assert any(b.source == 'MOVIE_CLIP' for b in cam.background_images)
    finally:
        bpy.data.scenes.remove(scene)
    # The points are marked on the clip itself: Match Camera puts the camera back where it was.
    match = _match_sample_camera(tmp_path / "capture.blend", tmp_path / "work")
    _assert_points_pose_the_camera(match)

"""The sample transfer scenes build headless, bake at low resolution and render one small frame."""

import json
import os
import subprocess

import bpy
import pytest

import conftest

pytestmark = pytest.mark.slow

FAST = ["--res", "20", "--frames", "8", "--samples", "2"]


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
    assert _not_blank(str(tmp_path / ("donut_%s.png" % fluid)))
    _check_domain(str(tmp_path / ("donut_%s.blend" % fluid)), eta, rho)


def test_honey_dipper_scene(tmp_path):
    _run("honey_dipper.py", tmp_path, *FAST)
    assert _not_blank(str(tmp_path / "honey_dipper.png"))
    _check_domain(str(tmp_path / "honey_dipper.blend"), 7.86, 1420.0)


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

"""Blender camera → OpenCV: the add-on's conversion agrees with Blender's own projection; when the
engine has `camera convert`, it agrees with the engine too."""

import json
import math
import subprocess

import bpy
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from viscoscope import camera_math, scene_export
from viscoscope.operators.camera import set_camera_from_opencv

CASES = [
    dict(fit='AUTO', res=(1920, 1080), pct=100, aspect=(1, 1), shift=(0, 0), lens=50, scale=1.0),
    dict(fit='AUTO', res=(1080, 1920), pct=50, aspect=(1, 1), shift=(0.1, -0.05), lens=28, scale=1.0),
    dict(fit='HORIZONTAL', res=(640, 480), pct=100, aspect=(2, 1), shift=(0, 0.2), lens=35, scale=0.01),
    dict(fit='VERTICAL', res=(800, 600), pct=75, aspect=(1, 1.5), shift=(-0.1, 0), lens=85, scale=2.0),
]


def _camera(ctx, case):
    r = ctx.scene.render
    r.resolution_x, r.resolution_y = case["res"]
    r.resolution_percentage = case["pct"]
    r.pixel_aspect_x, r.pixel_aspect_y = case["aspect"]
    ctx.scene.unit_settings.scale_length = case["scale"]
    bpy.ops.object.camera_add(location=(0.3, -1.2, 0.5), rotation=(math.radians(75), 0.1, math.radians(15)))
    cam = ctx.active_object
    cam.name = "Viscoscope test camera"
    cam.data.sensor_fit = case["fit"]
    cam.data.sensor_width, cam.data.sensor_height = 36.0, 24.0
    cam.data.lens = case["lens"]
    cam.data.shift_x, cam.data.shift_y = case["shift"]
    ctx.view_layer.update()
    return cam


POINTS = [(0, 0, 0), (0.1, 0.05, 0.2), (-0.15, 0.1, 0.05), (0.05, -0.2, 0.3), (0.2, 0.2, -0.1)]


@pytest.mark.parametrize("case", CASES, ids=lambda c: "%s-%dx%d" % (c["fit"], *c["res"]))
def test_projection_matches_blender(ctx, case):
    cam = _camera(ctx, case)
    data = scene_export.camera_dict(cam, ctx.scene)
    cv = camera_math.opencv_camera(data)
    w, h = cv["width"], cv["height"]
    assert (w, h) == (int(case["res"][0] * case["pct"] / 100), int(case["res"][1] * case["pct"] / 100))
    k = case["scale"]
    for p in POINTS:
        ndc = world_to_camera_view(ctx.scene, cam, Vector(p))
        u_blender = ndc.x * w - 0.5
        v_blender = (1.0 - ndc.y) * h - 0.5
        u, v = camera_math.project(cv, [c * k for c in p])
        assert u == pytest.approx(u_blender, abs=1e-3) and v == pytest.approx(v_blender, abs=1e-3)


def test_set_camera_from_opencv_round_trip(ctx):
    cam = _camera(ctx, CASES[2])
    cv = camera_math.opencv_camera(scene_export.camera_dict(cam, ctx.scene))
    before = cam.matrix_world.copy()
    cam.matrix_world.identity()
    set_camera_from_opencv(cam, cv["R"], cv["t"], ctx.scene.unit_settings.scale_length)
    for i in range(4):
        for j in range(4):
            assert cam.matrix_world[i][j] == pytest.approx(before[i][j], abs=1e-5)


def _engine_has(engine_path, *cmd):
    """True when every word of cmd is a listed sub-command (CLI11 prints them under "Subcommands:")."""
    prefix = []
    for word in cmd:
        out = subprocess.run([engine_path, *prefix, "--help"], capture_output=True, text=True).stdout
        listed = out.split("Subcommands:", 1)[1].split() if "Subcommands:" in out else []
        if word not in listed:
            return False
        prefix.append(word)
    return True


@pytest.mark.engine
@pytest.mark.parametrize("case", CASES, ids=lambda c: "%s-%dx%d" % (c["fit"], *c["res"]))
def test_camera_convert_parity_with_engine(ctx, tmp_path, engine_path, case):
    if not _engine_has(engine_path, "camera", "convert"):
        pytest.skip("this engine build has no `camera convert` yet")
    cam = _camera(ctx, case)
    src = tmp_path / "blender_camera.json"
    data = scene_export.export_camera(cam, ctx.scene, str(src))
    out = tmp_path / "camera.json"
    subprocess.run([engine_path, "camera", "convert", str(src), "--out", str(out)], check=True)
    theirs = json.loads(out.read_text())
    ours = camera_math.opencv_camera(data)
    assert (theirs["width"], theirs["height"]) == (ours["width"], ours["height"])
    for key in ("K", "R"):
        for r in range(3):
            assert theirs[key][r] == pytest.approx(ours[key][r], abs=1e-6), key
    assert theirs["t"] == pytest.approx(ours["t"], abs=1e-6)

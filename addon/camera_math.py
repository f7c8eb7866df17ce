"""Blender camera → OpenCV pinhole camera (no bpy).

This is the add-on's copy of the one conversion the engine owns (`viscoscope camera convert`); a
test checks the two agree and another checks this one against Blender's own projection.

Conventions: OpenCV looks down +Z with y pointing down, pixel centres at integer coordinates (the
image spans [-0.5, W-0.5]). A Blender camera looks down its local -Z with y up. Sensor fit, shift,
pixel aspect and resolution percentage follow Blender's viewplane computation.
"""

import math


def render_size(cam):
    """Rendered image size in pixels for a blender_camera dict."""
    pct = cam.get("resolution_percentage", 100)
    return (int(cam["resolution_x"] * pct / 100), int(cam["resolution_y"] * pct / 100))


def intrinsics(cam):
    """3x3 K (row-major list) and (width, height) for a blender_camera dict."""
    width, height = render_size(cam)
    aspx, aspy = float(cam.get("pixel_aspect_x", 1.0)), float(cam.get("pixel_aspect_y", 1.0))
    ycor = aspy / aspx
    fit = cam.get("sensor_fit", "AUTO")
    sensor = cam["sensor_height_mm"] if fit == "VERTICAL" else cam["sensor_width_mm"]
    if fit == "AUTO":
        fit = "HORIZONTAL" if aspx * width >= aspy * height else "VERTICAL"
    viewfac = width if fit == "HORIZONTAL" else ycor * height
    fx = cam["lens_mm"] * viewfac / sensor
    fy = fx / ycor
    cx = width / 2.0 - cam.get("shift_x", 0.0) * viewfac - 0.5
    cy = height / 2.0 + cam.get("shift_y", 0.0) * viewfac / ycor - 0.5
    return [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], (width, height)


def extrinsics(matrix_world):
    """OpenCV R (3x3) and t (3) mapping world points X to camera points R·X + t.

    matrix_world is the camera's 4x4 row-major world matrix in metres; any object scale is removed.
    """
    m = matrix_world
    cols = []
    for j in range(3):
        col = [m[i][j] for i in range(3)]
        norm = math.sqrt(sum(c * c for c in col))
        if norm == 0.0:
            raise ValueError("camera matrix_world has a zero-length axis")
        cols.append([c / norm for c in col])
    centre = [m[i][3] for i in range(3)]
    flip = (1.0, -1.0, -1.0)  # Blender camera axes → OpenCV camera axes
    rot = [[flip[r] * cols[r][c] for c in range(3)] for r in range(3)]  # F · R_cam→world^T
    t = [-sum(rot[r][c] * centre[c] for c in range(3)) for r in range(3)]
    return rot, t


def opencv_camera(cam):
    """The engine's camera.json content for a blender_camera dict."""
    K, (width, height) = intrinsics(cam)
    R, t = extrinsics(cam["matrix_world"])
    return {"K": K, "R": R, "t": t, "width": width, "height": height}


def project(opencv_cam, point):
    """Pixel (u, v) of a world point, or None when it is behind the camera."""
    R, t, K = opencv_cam["R"], opencv_cam["t"], opencv_cam["K"]
    pc = [sum(R[r][c] * point[c] for c in range(3)) + t[r] for r in range(3)]
    if pc[2] <= 0.0:
        return None
    return (K[0][0] * pc[0] / pc[2] + K[0][2], K[1][1] * pc[1] / pc[2] + K[1][2])

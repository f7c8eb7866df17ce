"""Camera: export the Blender camera for the engine, and match it from marked points (solvePnP)."""

import json
import math
import os

import bpy
from mathutils import Matrix, Vector

from .. import camera_math, engine, prefs, scene_export
from ..atomic_files import written_atomically


def scene_camera(scene):
    vs = scene.viscoscope
    cam = vs.camera or scene.camera
    if cam is None or cam.type != 'CAMERA':
        raise scene_export.ExportError("no camera: choose one in the Camera section")
    return cam


def set_camera_from_opencv(cam_obj, R, t, scale_length):
    """Place a Blender camera from OpenCV extrinsics (x_cam = R·X + t, X in metres)."""
    rt = Matrix(R).transposed()
    centre = -(rt @ Vector(t))
    rot = rt @ Matrix(((1, 0, 0), (0, -1, 0), (0, 0, -1)))
    mw = rot.to_4x4()
    mw.translation = centre / scale_length
    cam_obj.matrix_world = mw


def reprojection_rms(cam_json, world_m, image):
    errors = []
    for X, uv in zip(world_m, image):
        p = camera_math.project(cam_json, X)
        if p is None:
            return float("inf")
        errors.append((p[0] - uv[0]) ** 2 + (p[1] - uv[1]) ** 2)
    return math.sqrt(sum(errors) / len(errors)) if errors else float("nan")


def check_points_in_image(points, size):
    """Refuse a point whose pixel lies outside the image (pixel centres span [-0.5, size - 0.5]):
    pixels marked on footage of another size would pose the camera far off."""
    w, h = size
    for p in points:
        u, v = p.image
        if not (-0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5):
            raise scene_export.ExportError("point '%s' at pixel (%.0f, %.0f) is outside the %d × %d image"
                                           % (p.label, u, v, w, h))


def check_pose_plausible(solved, world_m, cam_data, scale_length):
    """Refuse a pose that puts a point behind the camera or beyond its clipping range: Blender
    would not draw such a point, so the footage cannot show it there."""
    near, far = cam_data.clip_start * scale_length, cam_data.clip_end * scale_length
    R, t = solved["R"], solved["t"]
    for X in world_m:
        depth = sum(R[2][c] * X[c] for c in range(3)) + t[2]
        if not near <= depth <= far:
            raise scene_export.ExportError(
                "the points put the camera %.3g m from them, outside its clip range %.3g–%.3g m: check the "
                "points' pixels and positions" % (depth, near, far))


class VISCOSCOPE_OT_export_camera(bpy.types.Operator):
    """Write the camera as viscoscope.blender_camera JSON and convert it with the engine"""
    bl_idname = "viscoscope.export_camera"
    bl_label = "Export Camera"

    def execute(self, context):
        try:
            cam = scene_camera(context.scene)
            folder = scene_export.work_dir(context.scene)
            path = os.path.join(folder, "blender_camera.json")
            scene_export.export_camera(cam, context.scene, path)
        except (scene_export.ExportError, OSError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, "Camera written to %s" % path)
        return {'FINISHED'}


class VISCOSCOPE_OT_add_camera_point(bpy.types.Operator):
    """Add a known point: its world position (e.g. the 3D cursor on the cup rim) and its pixel on the clip"""
    bl_idname = "viscoscope.add_camera_point"
    bl_label = "Add Point"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        vs = context.scene.viscoscope
        point = vs.points.add()
        point.label = "Point %d" % len(vs.points)
        point.world = context.scene.cursor.location
        vs.points_index = len(vs.points) - 1
        return {'FINISHED'}


class VISCOSCOPE_OT_remove_camera_point(bpy.types.Operator):
    """Remove the selected point"""
    bl_idname = "viscoscope.remove_camera_point"
    bl_label = "Remove Point"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return len(context.scene.viscoscope.points) > 0

    def execute(self, context):
        vs = context.scene.viscoscope
        vs.points.remove(vs.points_index)
        vs.points_index = max(0, min(vs.points_index, len(vs.points) - 1))
        return {'FINISHED'}


class VISCOSCOPE_OT_match_camera(bpy.types.Operator):
    """Solve the camera pose from at least 4 known points with the engine's solvePnP"""
    bl_idname = "viscoscope.match_camera"
    bl_label = "Match Camera from Points"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        scene = context.scene
        vs = scene.viscoscope
        try:
            if len(vs.points) < 4:
                raise scene_export.ExportError("mark at least 4 points, %d marked" % len(vs.points))
            cam = scene_camera(context.scene)
            size = tuple(vs.clip.size) if vs.clip else camera_math.render_size(scene_export.camera_dict(cam, scene))
            check_points_in_image(vs.points, size)
            exe = prefs.find_engine(context)
            folder = os.path.join(scene_export.work_dir(scene), "camera")
            os.makedirs(folder, exist_ok=True)
            k = scene.unit_settings.scale_length
            world = [[c * k for c in p.world] for p in vs.points]
            image = [list(p.image) for p in vs.points]
            bc_path = os.path.join(folder, "blender_camera.json")
            scene_export.export_camera(cam, scene, bc_path)
            intr_path = os.path.join(folder, "intrinsics.json")
            engine.run_quick([exe, "camera", "convert", bc_path, "--out", intr_path])
            pts_path = os.path.join(folder, "points.json")
            with written_atomically(pts_path) as fh:
                json.dump({"world": world, "image": image}, fh, allow_nan=False)
            out_path = os.path.join(folder, "camera.json")
            engine.run_quick([exe, "camera", "pnp", "--points", pts_path, "--intrinsics", intr_path, "--out", out_path])
            with open(out_path, encoding="utf-8") as fh:
                solved = json.load(fh)
            check_pose_plausible(solved, world, cam.data, k)
            set_camera_from_opencv(cam, solved["R"], solved["t"], k)
            err = solved.get("reprojection_error_px")
            vs.reprojection_error = float(err) if err is not None else reprojection_rms(solved, world, image)
        except (scene_export.ExportError, engine.EngineError, OSError, KeyError, ValueError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, "Camera matched, reprojection error %.2f px" % vs.reprojection_error)
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_export_camera, VISCOSCOPE_OT_add_camera_point, VISCOSCOPE_OT_remove_camera_point,
           VISCOSCOPE_OT_match_camera)

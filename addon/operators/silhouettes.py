"""Silhouettes: run the engine's extraction and show the masks over the footage."""

import json
import os

import bpy

from .. import engine, prefs, scene_export
from .runner import EngineOperator, is_running


def extraction_settings(scene):
    """The Silhouettes panel as a job's "extraction" object (the engine's names): what both Preview
    Silhouettes and Identify extract the video with."""
    vs = scene.viscoscope
    settings = {"mog2_variance_threshold": vs.var_threshold, "threshold": vs.mask_threshold,
                "mog2_shadow_threshold": vs.shadow_threshold, "edge_coverage": vs.edge_coverage,
                "close_kernel_px": vs.close_diameter, "open_kernel_px": vs.open_diameter, "min_blob_px": vs.min_blob}
    if vs.background == 'PLATE_FRAME':
        settings["clean_plate_frame"] = vs.clean_plate_frame
    elif vs.background == 'PLATE_IMAGE':
        plate = bpy.path.abspath(vs.clean_plate_image) if vs.clean_plate_image else ""
        if not plate or not os.path.isfile(plate):
            raise scene_export.ExportError("clean plate image not found: %s" % (plate or "none chosen"))
        settings["clean_plate"] = plate
    else:
        settings["background_frames"] = vs.background_frames
    return settings


def reference_video(scene):
    """The reference video's absolute path; ExportError when there is none."""
    vs = scene.viscoscope
    video = bpy.path.abspath(vs.video_path) if vs.video_path else ""
    if not video or not os.path.isfile(video):
        raise scene_export.ExportError("reference video not found: %s" % (video or "none chosen"))
    return video


def made_with(scene):
    """What a preview made now would be made from (compared with the shown preview's)."""
    try:
        return json.dumps([reference_video(scene), extraction_settings(scene)], sort_keys=True)
    except scene_export.ExportError as exc:
        return str(exc)


def show_masks(context, out_dir):
    """Overlay DIR/masks/mask_*.png on the camera background (half transparent, in front)."""
    masks = sorted(f for f in os.listdir(os.path.join(out_dir, "masks")) if f.startswith("mask_") and f.endswith(".png"))
    if not masks:
        raise FileNotFoundError("the engine wrote no masks in %s" % os.path.join(out_dir, "masks"))
    img = bpy.data.images.load(os.path.join(out_dir, "masks", masks[0]), check_existing=True)
    img.source = 'SEQUENCE'
    img.name = "Viscoscope Silhouettes"
    vs = context.scene.viscoscope
    cam = vs.camera or context.scene.camera
    if cam is not None and cam.type == 'CAMERA':
        cam.data.show_background_images = True
        bg = next((b for b in cam.data.background_images if b.source == 'IMAGE' and b.image == img), None)
        bg = bg or cam.data.background_images.new()
        bg.source = 'IMAGE'
        bg.image = img
        bg.image_user.frame_duration = len(masks)
        bg.image_user.frame_start = context.scene.frame_start
        bg.image_user.use_auto_refresh = True
        bg.alpha = 0.5
        bg.display_depth = 'FRONT'
    return img


class VISCOSCOPE_OT_preview_silhouettes(EngineOperator, bpy.types.Operator):
    """Extract the liquid's silhouettes from the video, as Identify will, and show them over the footage"""
    bl_idname = "viscoscope.preview_silhouettes"
    bl_label = "Preview Silhouettes"
    job_kind = "extract"

    @classmethod
    def poll(cls, context):
        return not is_running("extract")

    def prepare(self, context):
        video = reference_video(context.scene)
        exe = prefs.find_engine(context)
        out_dir = os.path.join(scene_export.work_dir(context.scene), "silhouettes")
        os.makedirs(out_dir, exist_ok=True)
        self.made_with = made_with(context.scene)
        return engine.extract_args(exe, video, out_dir, extraction_settings(context.scene)), out_dir

    def on_success(self, context, out_dir):
        show_masks(context, out_dir)
        context.scene.viscoscope.preview_made_with = self.made_with


classes = (VISCOSCOPE_OT_preview_silhouettes,)

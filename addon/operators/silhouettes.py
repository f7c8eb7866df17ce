"""Silhouettes: run the engine's extraction and show the masks over the footage."""

import os

import bpy

from .. import engine, prefs, scene_export
from .runner import EngineOperator, is_running


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
    """Extract the liquid's silhouettes from the video and show them over the footage"""
    bl_idname = "viscoscope.preview_silhouettes"
    bl_label = "Preview Silhouettes"
    job_kind = "extract"

    @classmethod
    def poll(cls, context):
        return not is_running("extract")

    def prepare(self, context):
        vs = context.scene.viscoscope
        video = bpy.path.abspath(vs.video_path) if vs.video_path else ""
        if not video or not os.path.isfile(video):
            raise scene_export.ExportError("reference video not found: %s" % (video or "none chosen"))
        exe = prefs.find_engine(context)
        out_dir = os.path.join(scene_export.work_dir(context.scene), "silhouettes")
        os.makedirs(out_dir, exist_ok=True)
        options = {"background_frames": vs.background_frames, "var_threshold": vs.var_threshold,
                   "threshold": vs.mask_threshold, "shadow_threshold": vs.shadow_threshold,
                   "edge_coverage": vs.edge_coverage,
                   "close": vs.close_diameter, "open": vs.open_diameter, "min_blob": vs.min_blob}
        return engine.extract_args(exe, video, out_dir, options), out_dir

    def on_success(self, context, out_dir):
        show_masks(context, out_dir)


classes = (VISCOSCOPE_OT_preview_silhouettes,)

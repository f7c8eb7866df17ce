"""Reference footage: the video becomes a Movie Clip, the camera's background, and the scene's
frame range and frame rate."""

import os

import bpy
from bpy_extras.io_utils import ImportHelper


def load_reference(context, path):
    """Load a video as the reference clip; returns the MovieClip. Raises ValueError with one line."""
    path = bpy.path.abspath(path) if path else ""
    if not path:
        raise ValueError("No video chosen")
    if not os.path.isfile(path):
        raise ValueError("Video not found: %s" % path)
    try:
        clip = bpy.data.movieclips.load(path, check_existing=True)
    except RuntimeError as exc:
        raise ValueError("Cannot read video %s: %s" % (path, str(exc).strip().splitlines()[-1])) from exc
    if clip.size[0] == 0 or clip.frame_duration < 1:
        raise ValueError("Cannot decode video %s (no frames)" % path)
    scene = context.scene
    vs = scene.viscoscope
    vs.video_path = path
    vs.clip = clip
    scene.active_clip = clip
    scene.frame_start = clip.frame_start
    scene.frame_end = clip.frame_start + clip.frame_duration - 1
    if clip.fps > 0:
        fps = max(1, int(round(clip.fps)))
        scene.render.fps = fps
        scene.render.fps_base = fps / clip.fps
    scene.render.resolution_x, scene.render.resolution_y = clip.size
    scene.render.resolution_percentage = 100
    cam = vs.camera or scene.camera
    if cam is not None and cam.type == 'CAMERA':
        set_camera_background(cam, clip)
    return clip


def set_camera_background(cam_obj, clip):
    cam = cam_obj.data
    cam.show_background_images = True
    bg = next((b for b in cam.background_images if b.source == 'MOVIE_CLIP'), None) or cam.background_images.new()
    bg.source = 'MOVIE_CLIP'
    bg.clip = clip
    bg.use_camera_clip = False
    bg.alpha = 1.0
    bg.display_depth = 'BACK'
    return bg


class VISCOSCOPE_OT_load_video(bpy.types.Operator, ImportHelper):
    """Load the reference video as a Movie Clip, set it as the camera background and match the scene's frame range and rate"""
    bl_idname = "viscoscope.load_video"
    bl_label = "Load Video"
    bl_options = {'REGISTER', 'UNDO'}

    filter_glob: bpy.props.StringProperty(default="*.mp4;*.mov;*.avi;*.mkv;*.webm;*.m4v", options={'HIDDEN'})

    def execute(self, context):
        try:
            clip = load_reference(context, self.filepath)
        except ValueError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, "Loaded %s: %d frames at %.3g fps" % (clip.name, clip.frame_duration, clip.fps))
        return {'FINISHED'}


class VISCOSCOPE_OT_add_run(bpy.types.Operator):
    """Fit another run of this liquid together with this scene's: a scene of this file with its own
    container and reference (another volume, lock height or flux), sharing this Fluid Material"""
    bl_idname = "viscoscope.add_run"
    bl_label = "Add Run"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        vs = context.scene.viscoscope
        taken = {context.scene} | {run.scene for run in vs.runs}
        run = vs.runs.add()
        run.scene = next((s for s in bpy.data.scenes if s not in taken), None)
        vs.runs_index = len(vs.runs) - 1
        return {'FINISHED'}


class VISCOSCOPE_OT_remove_run(bpy.types.Operator):
    """Fit without the selected run"""
    bl_idname = "viscoscope.remove_run"
    bl_label = "Remove Run"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return len(context.scene.viscoscope.runs) > 0

    def execute(self, context):
        vs = context.scene.viscoscope
        vs.runs.remove(min(vs.runs_index, len(vs.runs) - 1))
        vs.runs_index = max(0, min(vs.runs_index, len(vs.runs) - 1))
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_load_video, VISCOSCOPE_OT_add_run, VISCOSCOPE_OT_remove_run)

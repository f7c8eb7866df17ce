"""The capture scene: a cup with a hole in its bottom standing above the ground, a camera looking at
it, the honey fluid material, ready for the workflow (Reference → Camera → Identify).

    blender -b --factory-startup --python sample_scenes/capture_scene.py -- --out DIR [--clip]
writes DIR/capture.blend. With --clip (needs the engine: VISCOSCOPE_ENGINE, preferences or
build/bin), it also simulates the pour with the Viscoscope engine at a resolution identification
does not use, renders it with Cycles into DIR/reference.mp4 and loads that as the reference video,
so a new user can click through the whole workflow on embedded data.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


CLIP_SIZE = (320, 180)  # the reference clip's pixels (small: Cycles renders it on a CPU)


def mark_points(scene):
    """The points' pixels as the artist would mark them on footage shot with this camera, in the
    camera's image: the render size, which Load Video sets to the clip's."""
    import bpy
    from viscoscope import camera_math, scene_export
    bpy.context.view_layer.update()
    cv = camera_math.opencv_camera(scene_export.camera_dict(scene.camera, scene))
    for p in scene.viscoscope.points:
        p.image = camera_math.project(cv, list(p.world))


def build():
    import bpy
    scene = _common.empty_scene()
    from viscoscope.operators import container
    cup, ground, domain = container.add_cup(bpy.context, (0.0, 0.0, 0.0))
    cup.data.materials.append(_common.simple_material("Cup", (0.85, 0.85, 0.9), 0.3))
    ground.data.materials.append(_common.simple_material("Table", (0.35, 0.3, 0.25), 0.7))
    scene.viscoscope.fill_volume = 1.7e-4
    _common.set_fluid(scene, "Honey (capture)", 8.0, 1400.0, 0.0, (0.85, 0.5, 0.08))
    scene.viscoscope.sim_resolution = 32
    scene.viscoscope.sim_frames = 24
    _common.add_camera(scene, (0.0, -0.45, 0.12), (0.0, 0.0, 0.07), lens=50)
    _common.add_lights(scene, (0, 0, 0.06), scale=0.5)
    # The render size is the reference clip's, so that the camera's image is the footage's.
    scene.render.resolution_x, scene.render.resolution_y = CLIP_SIZE
    scene.render.fps = 30
    scene.frame_start, scene.frame_end = 1, 24
    # Four reference points for "Match camera from points": the cup's rim and the base.
    for label, world in (("rim left", (-0.046, 0.0, 0.114)), ("rim right", (0.046, 0.0, 0.114)),
                         ("base left", (-0.046, 0.0, 0.05)), ("base right", (0.046, 0.0, 0.05))):
        p = scene.viscoscope.points.add()
        p.label, p.world = label, world
    mark_points(scene)
    return scene


def render_reference_clip(scene, out_dir, samples=4):
    """Simulate (engine), import the surface, render a small mp4 and load it as the reference."""
    import bpy
    from viscoscope.operators import reference
    vs = scene.viscoscope
    vs.work_dir = os.path.join(out_dir, "reference_sim")
    # Like `synth`: 4/3 of the Identify panel's grid and another particle seed, so that the clip is
    # not made by the solver settings identification scores it with.
    transfer_resolution, transfer_seed = vs.sim_resolution, vs.sim_seed
    vs.sim_resolution = round(vs.identify_resolution * 4 / 3)
    vs.sim_seed = vs.sim_seed + 1
    result = bpy.ops.viscoscope.simulate('EXEC_DEFAULT')
    if result != {'FINISHED'}:
        raise SystemExit("error: the reference simulation failed: %s" % vs.simulate_job.error)
    liquid = bpy.data.objects["Viscoscope Liquid"]
    scene.render.engine = 'CYCLES'
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = CLIP_SIZE
    scene.render.image_settings.file_format = 'FFMPEG'
    scene.render.ffmpeg.format = 'MPEG4'
    scene.render.ffmpeg.codec = 'H264'
    scene.render.ffmpeg.constant_rate_factor = 'HIGH'
    clip_path = os.path.join(out_dir, "reference.mp4")
    scene.render.filepath = clip_path
    scene.frame_end = scene.frame_start + vs.sim_frames
    bpy.ops.render.render(animation=True)
    # The reference is footage now: drop the simulated liquid, keep the clip.
    volume = liquid.modifiers[0].object
    bpy.data.objects.remove(liquid)
    bpy.data.objects.remove(volume)
    vs.work_dir = "//viscoscope"
    vs.sim_resolution, vs.sim_seed = transfer_resolution, transfer_seed
    reference.load_reference(bpy.context, clip_path)
    mark_points(scene)  # on the clip as decoded
    return clip_path


if __name__ == "__main__":
    import sys as _sys
    argv = _sys.argv[_sys.argv.index("--") + 1:] if "--" in _sys.argv else []
    with_clip = "--clip" in argv
    if with_clip:
        argv.remove("--clip")
        _sys.argv = _sys.argv[:_sys.argv.index("--") + 1] + argv
    args = _common.parse_args()
    scene = build()
    if with_clip:
        render_reference_clip(scene, os.path.abspath(args.out), samples=args.samples)
    _common.save(os.path.join(args.out, "capture.blend"))

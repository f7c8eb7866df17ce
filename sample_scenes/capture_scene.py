"""The capture scene: a cup with a hole in its bottom standing above the ground, a camera looking at
it, the honey fluid material, ready for the workflow (Reference → Camera → Identify).

    blender -b --factory-startup --python sample_scenes/capture_scene.py -- --out DIR [--clip] [--frames 24]
writes DIR/capture.blend. With --clip (needs the engine: VISCOSCOPE_ENGINE, preferences or
build/bin), it also simulates the pour with the Viscoscope engine at a resolution identification
does not use, renders it with Cycles into DIR/reference.mp4 and loads that as the reference video,
so a new user can click through the whole workflow on embedded data. --eta ETA sets the honey's η
(Pa·s) the clip is simulated with; --mantaflow RES adds Blender's own liquid solver on the same cup
(add_mantaflow) at that resolution, for Calibrate Mantaflow to Footage; --frames the clip's length (30 fps).
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


def build(frames=24):
    import bpy
    scene = _common.empty_scene()
    from viscoscope.operators import container
    cup, ground, domain = container.add_cup(bpy.context, (0.0, 0.0, 0.0))
    cup.data.materials.append(_common.simple_material("Cup", (0.85, 0.85, 0.9), 0.3))
    ground.data.materials.append(_common.simple_material("Table", (0.35, 0.3, 0.25), 0.7))
    scene.viscoscope.fill_volume = 1.7e-4
    _common.set_fluid(scene, {"description": "Honey (capture)", "viscosity": 8.0, "density": 1400.0,
                             "surface_tension": 0.0, "color": (0.85, 0.5, 0.08)})
    scene.viscoscope.sim_resolution = 32
    scene.viscoscope.sim_frames = frames
    _common.add_camera(scene, (0.0, -0.45, 0.12), (0.0, 0.0, 0.07), lens=50)
    _common.add_lights(scene, (0, 0, 0.06), scale=0.5)
    # The render size is the reference clip's, so that the camera's image is the footage's.
    scene.render.resolution_x, scene.render.resolution_y = CLIP_SIZE
    scene.render.fps = 30
    scene.frame_start, scene.frame_end = 1, frames
    # Four reference points for "Match camera from points": the cup's rim and the base.
    for label, world in (("rim left", (-0.046, 0.0, 0.114)), ("rim right", (0.046, 0.0, 0.114)),
                         ("base left", (-0.046, 0.0, 0.05)), ("base right", (0.046, 0.0, 0.05))):
        p = scene.viscoscope.points.add()
        p.label, p.world = label, world
    mark_points(scene)
    return scene


def add_mantaflow(scene, resolution=32):
    """A Mantaflow liquid domain over the Viscoscope domain's box (its bottom border the ground), the
    cup as a collision effector and the cup's fill as a liquid flow object."""
    import math
    import tempfile
    import bpy
    from mathutils import Vector
    vs = scene.viscoscope
    box = next(o for o in scene.objects if o.viscoscope.role == 'DOMAIN')
    frames = scene.frame_start, scene.frame_end
    corners = [box.matrix_world @ Vector(c) for c in box.bound_box]
    lo = [min(c[i] for c in corners) for i in range(3)]
    hi = [max(c[i] for c in corners) for i in range(3)]
    domain = _common.make_domain(scene, lo, hi, resolution, scene.frame_end - scene.frame_start + 1,
                                 name="Mantaflow Domain",
                                 cache_dir=tempfile.mkdtemp(prefix="viscoscope_capture_mantaflow_"))
    scene.frame_start, scene.frame_end = frames  # make_domain sets its own
    ds = domain.modifiers["Fluid"].domain_settings
    ds.use_collision_border_bottom = True  # the ground
    domain.display_type = 'BOUNDS'
    cup = vs.cup
    cs = cup.viscoscope
    # Mantaflow lets liquid through a wall thinner than about two cells (the cup's 3 mm leaked at
    # 5 mm cells): its effector is the cup with the wall thickened outwards, inside and hole unchanged.
    from viscoscope import cup_mesh
    cell = max(h - l for l, h in zip(lo, hi)) / resolution
    effector = bpy.data.objects.new("Mantaflow Cup", bpy.data.meshes.new("Mantaflow Cup"))
    scene.collection.objects.link(effector)
    es = effector.viscoscope
    for attr in ("cup_inner_radius", "cup_height", "cup_bottom", "cup_hole_radius"):
        setattr(es, attr, getattr(cs, attr))
    es.cup_wall = max(cs.cup_wall, 2.0 * cell)
    cup_mesh.build_cup_mesh(effector.data, es)
    effector.matrix_world = cup.matrix_world
    effector.hide_render = True
    effector.display_type = 'WIRE'
    _common.make_effector(effector)
    inner_bottom = cup.matrix_world.translation.z + cs.cup_bottom
    fill = vs.fill_volume / (math.pi * cs.cup_inner_radius ** 2)
    bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=cs.cup_inner_radius, depth=fill,
                                        location=(cup.matrix_world.translation.x, cup.matrix_world.translation.y,
                                                  inner_bottom + fill / 2))
    liquid = bpy.context.active_object
    liquid.name = "Mantaflow Liquid"
    liquid.hide_render = True
    _common.make_flow(liquid, behavior='GEOMETRY')
    _common.apply_preset_to_domain(domain)  # the Fluid Material's formula viscosity_value
    return domain


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
    extra = {}
    for name in ("--eta", "--mantaflow"):
        if name in argv:
            i = argv.index(name)
            extra[name] = float(argv[i + 1])
            del argv[i:i + 2]
    _sys.argv = _sys.argv[:_sys.argv.index("--") + 1] + argv
    args = _common.parse_args(default_frames=24)
    scene = build(args.frames)
    if "--eta" in extra:
        scene.viscoscope.fluid.viscosity = extra["--eta"]
    if with_clip:
        render_reference_clip(scene, os.path.abspath(args.out), samples=args.samples)
    if "--mantaflow" in extra:
        add_mantaflow(scene, int(extra["--mantaflow"]))
    _common.save(os.path.join(args.out, "capture.blend"))

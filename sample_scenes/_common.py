"""Helpers shared by the sample-scene builders (run inside Blender, headless).

    blender -b --factory-startup --python sample_scenes/<scene>.py -- --out DIR [--res N] [--frames N]
        [--samples N] [--no-bake] [--no-render] [--fluid NAME | --preset FILE] [--solver mantaflow|viscoscope]

A transfer scene (donut, honey dipper) is simulated either by Blender's Mantaflow, with the fluid
applied to its domain, or by the Viscoscope engine through the Transfer panel ("Simulate with
Viscoscope"), which carries the whole material: a shear-thinning or yield-stress preset as well as a
Newtonian one. Its objects always have their Viscoscope roles; Mantaflow's modifiers only when
Mantaflow simulates.
"""

import argparse
import math
import os
import sys
import tempfile

import bpy

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def parse_args(default_res=32, default_frames=20, fluids=None):
    """The command line after "--". `fluids` (name → fluid values) adds --fluid, --preset and --solver."""
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=os.path.join(REPO, "build", "sample_scenes"))
    parser.add_argument("--res", type=int, default=default_res,
                        help="grid cells along the domain's longest side (either solver)")
    parser.add_argument("--frames", type=int, default=default_frames)
    parser.add_argument("--samples", type=int, default=8, help="Cycles samples")
    parser.add_argument("--no-bake", action="store_true", help="build and save the scene, simulate nothing")
    parser.add_argument("--no-render", action="store_true")
    if fluids:
        parser.add_argument("--fluid", choices=list(fluids), default=next(iter(fluids)))
        parser.add_argument("--preset", help="a Viscoscope fluid preset file (.py) to use instead of --fluid")
        parser.add_argument("--solver", choices=("mantaflow", "viscoscope"), default="mantaflow")
    return parser.parse_args(argv)


def enable_addon():
    """Enable the add-on from this checkout as the package "viscoscope" (unless installed)."""
    import addon_utils
    try:
        import viscoscope  # noqa: F401  (installed)
    except ImportError:
        link_dir = tempfile.mkdtemp(prefix="viscoscope_addon_")
        os.symlink(os.path.join(REPO, "addon"), os.path.join(link_dir, "viscoscope"))
        sys.path.insert(0, link_dir)
    mod = addon_utils.enable("viscoscope", default_set=True, handle_error=None)
    if mod is None:
        raise SystemExit("error: could not enable the Viscoscope add-on")
    return mod


def empty_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    enable_addon()
    scene = bpy.context.scene
    scene.unit_settings.system = 'METRIC'
    scene.unit_settings.scale_length = 1.0
    return scene


def set_fluid(scene, values):
    """The scene's Fluid Material set to `values` (fluid property → value; the rest keep defaults)."""
    fluid = scene.viscoscope.fluid
    fluid.roughness, fluid.transmission = 0.1, 0.5
    for key, value in values.items():
        setattr(fluid, key, value)
    return fluid


def use_fluid(scene, fluid):
    """The scene's Fluid Material from `fluid`: fluid property → value, or a preset file's path,
    loaded as the panel's preset menu loads it."""
    if not isinstance(fluid, str):
        set_fluid(scene, fluid)
        return
    if not os.path.isfile(fluid):
        raise SystemExit("error: --preset: no such file: %s" % fluid)
    run_operator(bpy.ops.viscoscope.fluid_preset_load, "--preset", filepath=os.path.abspath(fluid))


def add_camera(scene, location, target, lens=50.0):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.data.lens = lens
    cam.location = location
    direction = (target[0] - location[0], target[1] - location[1], target[2] - location[2])
    from mathutils import Vector
    cam.rotation_euler = Vector(direction).to_track_quat('-Z', 'Y').to_euler()
    scene.camera = cam
    scene.viscoscope.camera = cam
    return cam


def add_lights(scene, target=(0, 0, 0), scale=1.0):
    key = bpy.data.objects.new("Key Light", bpy.data.lights.new("Key Light", 'AREA'))
    key.data.energy = 60.0 * scale ** 2
    key.data.size = 0.5 * scale
    key.location = (target[0] + 0.6 * scale, target[1] - 0.5 * scale, target[2] + 0.8 * scale)
    key.rotation_euler = (math.radians(45), 0, math.radians(50))
    rim = bpy.data.objects.new("Rim Light", bpy.data.lights.new("Rim Light", 'POINT'))
    rim.data.energy = 20.0 * scale ** 2
    rim.location = (target[0] - 0.5 * scale, target[1] + 0.6 * scale, target[2] + 0.5 * scale)
    for light in (key, rim):
        scene.collection.objects.link(light)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.06, 1.0)
    scene.world = world


def add_mesh_object(scene, name, verts, faces, material=None):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.validate()
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    if material is not None:
        mesh.materials.append(material)
    return obj


def cylinder(scene, name, radius, depth, location):
    """A vertical cylinder (its axis along Z) centred at `location`."""
    bpy.ops.mesh.primitive_cylinder_add(radius=radius, depth=depth, location=location)
    obj = bpy.context.active_object
    obj.name = name
    return obj


def simple_material(name, color, roughness=0.5):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = tuple(color) + (1.0,)
    bsdf.inputs["Roughness"].default_value = roughness
    mat.diffuse_color = tuple(color) + (1.0,)
    return mat


def torus(scene, name, major, minor, location, material=None, segments=48, sides=16):
    verts, faces = [], []
    for i in range(segments):
        a = 2 * math.pi * i / segments
        for j in range(sides):
            b = 2 * math.pi * j / sides
            r = major + minor * math.cos(b)
            verts.append((r * math.cos(a), r * math.sin(a), minor * math.sin(b)))
    for i in range(segments):
        for j in range(sides):
            i1, j1 = (i + 1) % segments, (j + 1) % sides
            faces.append((i * sides + j, i1 * sides + j, i1 * sides + j1, i * sides + j1))
    obj = add_mesh_object(scene, name, verts, faces, material)
    obj.location = location
    for poly in obj.data.polygons:
        poly.use_smooth = True
    return obj


def make_domain(scene, lo, hi, res, frames, name="Fluid Domain", cache_dir=None):
    """A Mantaflow liquid domain spanning [lo, hi] with its cache in cache_dir (default: a temp folder)."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    dom = bpy.context.active_object
    dom.name = name
    dom.location = tuple((l + h) / 2 for l, h in zip(lo, hi))
    dom.scale = tuple(h - l for l, h in zip(lo, hi))
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    mod = dom.modifiers.new("Fluid", 'FLUID')
    mod.fluid_type = 'DOMAIN'
    ds = mod.domain_settings
    ds.domain_type = 'LIQUID'
    ds.resolution_max = res
    ds.use_mesh = True
    ds.cache_type = 'ALL'
    ds.cache_frame_start = 1
    ds.cache_frame_end = frames
    ds.cache_directory = cache_dir or tempfile.mkdtemp(prefix="viscoscope_mantaflow_")
    scene.frame_start, scene.frame_end = 1, frames
    return dom


def make_flow(obj, flow_type='LIQUID', behavior='INFLOW', velocity=(0, 0, 0)):
    mod = obj.modifiers.new("Fluid", 'FLUID')
    mod.fluid_type = 'FLOW'
    fs = mod.flow_settings
    fs.flow_type = flow_type
    fs.flow_behavior = behavior
    fs.flow_source = 'MESH'
    fs.use_initial_velocity = any(velocity)
    fs.velocity_coord = velocity
    return mod


def make_effector(obj):
    mod = obj.modifiers.new("Fluid", 'FLUID')
    mod.fluid_type = 'EFFECTOR'
    mod.effector_settings.effector_type = 'COLLISION'
    mod.effector_settings.use_plane_init = False
    return mod


def run_operator(operator, what, *args, why=None, **kwargs):
    """Run a Viscoscope operator; one line and exit when it fails (in the background Blender
    raises its error report as a RuntimeError: its last line, after "Error: ", is the reason;
    why() gives it for an operator that returns CANCELLED)."""
    try:
        result = operator(*args, **kwargs)
    except RuntimeError as exc:
        raise SystemExit("error: %s: %s" % (what, str(exc).strip().splitlines()[-1].split("Error: ", 1)[-1])) from None
    if result != {'FINISHED'}:
        raise SystemExit("error: %s failed%s" % (what, ": " + why() if why else ""))


def apply_preset_to_domain(dom):
    bpy.context.view_layer.objects.active = dom
    run_operator(bpy.ops.viscoscope.apply_to_domain, "applying the fluid to the domain")


def bake(dom):
    bpy.context.view_layer.objects.active = dom
    with bpy.context.temp_override(object=dom, active_object=dom):
        result = bpy.ops.fluid.bake_all()
    if result != {'FINISHED'}:
        raise SystemExit("error: Mantaflow bake failed: %s" % result)


def transfer_domain(scene, lo, hi, res, frames, solver, cache_dir=None):
    """The domain over [lo, hi] with `res` cells along its longest side: Mantaflow's liquid domain
    (named "Fluid Domain"), or for the Viscoscope engine a box that only bounds the simulation."""
    if solver == "mantaflow":
        dom = make_domain(scene, lo, hi, res, frames, cache_dir=cache_dir)
    else:
        from viscoscope.operators import container
        dom = container.add_domain(bpy.context, lo, hi, name="Fluid Domain")
        scene.frame_start, scene.frame_end = 1, frames
    dom.viscoscope.role = 'DOMAIN'
    scene.viscoscope.sim_resolution, scene.viscoscope.sim_frames = res, frames
    return dom


def transfer_source(obj, solver, speed, pour_seconds):
    """`obj`, a round source of liquid pouring straight down at `speed` m/s: a Mantaflow inflow (it
    pours all along), or a Viscoscope emitter disc of the object's radius at its origin, pouring for
    the first `pour_seconds`."""
    obj.hide_render = True
    obj.rotation_euler = (math.pi, 0.0, 0.0)  # the emitter pours along its local +Z
    radius = obj.dimensions.x / 2
    ov = obj.viscoscope
    ov.role = 'EMITTER'
    ov.emitter_radius = radius / obj.scale.x
    ov.emitter_flux = math.pi * radius ** 2 * speed
    ov.emitter_start, ov.emitter_end = 0.0, pour_seconds
    if solver == "mantaflow":
        make_flow(obj, velocity=(0.0, 0.0, -speed))


def transfer_solid(obj, solver):
    """`obj` as an obstacle: a Mantaflow collision effector, or a Viscoscope mesh solid."""
    obj.viscoscope.role = 'SOLID'
    if solver == "mantaflow":
        make_effector(obj)


def simulate(scene, dom, solver, work_dir):
    """Bake Mantaflow's domain, or run the Viscoscope engine on the scene (its Transfer panel's
    "Simulate with Viscoscope", working in work_dir) and import its surface with the fluid material."""
    if solver == "mantaflow":
        bake(dom)
        return
    scene.viscoscope.work_dir = work_dir
    run_operator(bpy.ops.viscoscope.simulate, "the Viscoscope simulation", 'EXEC_DEFAULT',
                 why=lambda: scene.viscoscope.simulate_job.error)


def run_name(args):
    """What a transfer scene's files are named after: the preset file, or the sample fluid."""
    return os.path.splitext(os.path.basename(args.preset))[0] if args.preset else args.fluid


def finish(scene, dom, args, name):
    """Simulate with args.solver (unless --no-bake), render the last frame (unless --no-render) and
    save DIR/<name>.blend."""
    if not args.no_bake:
        simulate(scene, dom, args.solver, os.path.join(os.path.abspath(args.out), name + "_viscoscope"))
    if not args.no_render:
        render(scene, os.path.join(args.out, name + ".png"), args.samples, frame=args.frames)
    save(os.path.join(args.out, name + ".blend"))


def render(scene, path, samples=4, resolution=(320, 240), frame=None):
    scene.render.engine = 'CYCLES'
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.device = 'CPU'
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = 'PNG'
    scene.render.filepath = path
    if frame is not None:
        scene.frame_set(frame)
    bpy.ops.render.render(write_still=True)
    return path


def save(path):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    print("saved", path)

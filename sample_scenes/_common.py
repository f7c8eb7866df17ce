"""Helpers shared by the sample-scene builders (run inside Blender, headless).

    blender -b --factory-startup --python sample_scenes/<scene>.py -- --out DIR [--res N] [--frames N]
        [--samples N] [--no-bake] [--no-render]
"""

import argparse
import math
import os
import sys
import tempfile

import bpy

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def parse_args(default_res=32, default_frames=20):
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=os.path.join(REPO, "build", "sample_scenes"))
    parser.add_argument("--res", type=int, default=default_res, help="Mantaflow resolution_max")
    parser.add_argument("--frames", type=int, default=default_frames)
    parser.add_argument("--samples", type=int, default=8, help="Cycles samples")
    parser.add_argument("--no-bake", action="store_true")
    parser.add_argument("--no-render", action="store_true")
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


def set_fluid(scene, description, eta, rho, sigma, color):
    fluid = scene.viscoscope.fluid
    fluid.description = description
    fluid.viscosity, fluid.density, fluid.surface_tension = eta, rho, sigma
    fluid.color = color
    fluid.roughness, fluid.transmission = 0.1, 0.5
    return fluid


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


def apply_preset_to_domain(dom):
    bpy.context.view_layer.objects.active = dom
    result = bpy.ops.viscoscope.apply_to_domain()
    if result != {'FINISHED'}:
        raise SystemExit("error: applying the fluid to the domain failed")


def bake(dom):
    bpy.context.view_layer.objects.active = dom
    with bpy.context.temp_override(object=dom, active_object=dom):
        result = bpy.ops.fluid.bake_all()
    if result != {'FINISHED'}:
        raise SystemExit("error: Mantaflow bake failed: %s" % result)


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

"""Renders a synthetic reference for `viscoscope synth` (run inside Blender, never imported):

    blender -b --factory-startup --python-exit-code 1 --python render_reference.py -- render.json

render.json (written by native/src/cli/synth_command.cpp):
    camera          a "viscoscope.blender_camera" at the render size (resolution percentage 100)
    samples, seed   Cycles samples per pixel and noise seed
    solids          OBJ of the container (world coordinates, Z up, metres) or null
    ground_height   z of the ground plane, or null for none
    clean_plate     PNG path: the scene without liquid
    frames          [{"mesh": liquid surface OBJ, "image": PNG path, "mask_image": PNG path (optional)}, ...]
    simulation_digest  which run the meshes are from (the engine compares it; unused here)

An image that is already there is not rendered again: the engine keeps those a cancelled synth of
the same simulation and settings left, and removes all others first.

The look is a plain studio shot: a grey backdrop, one sun, an opaque light cup, a mid-grey floor
and honey-coloured liquid. Cycles without denoising, Standard view transform, so the noise and
tones are those of a plain camera, not of a filmic grade. Renders the clean plate first. A frame's
"mask_image" is the liquid alone: white and lit by nothing but itself, seen by the camera's rays only,
before the solids and the floor left black by a black world and no sun, so that Blender's own ray
tracing says what the camera sees of it.
"""

import json
import os
import sys

import bpy
from mathutils import Matrix


def read_obj(path):
    """Vertices and faces of an OBJ (1-based, optionally v/vt/vn indices)."""
    verts, faces = [], []
    with open(path, encoding="ascii") as fh:
        for line in fh:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif parts[0] == "f":
                faces.append(tuple(int(p.split("/")[0]) - 1 for p in parts[1:]))
    return verts, faces


def add_mesh(scene, name, path, material):
    verts, faces = read_obj(path)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def principled(name, colour, roughness):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    return material


def set_up(spec):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = spec["samples"]
    scene.cycles.use_denoising = False
    scene.cycles.seed = spec["seed"]
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"

    cam = spec["camera"]
    scene.render.resolution_x = cam["resolution_x"]
    scene.render.resolution_y = cam["resolution_y"]
    scene.render.resolution_percentage = int(cam["resolution_percentage"])
    scene.render.pixel_aspect_x = cam["pixel_aspect_x"]
    scene.render.pixel_aspect_y = cam["pixel_aspect_y"]
    data = bpy.data.cameras.new("camera")
    data.lens = cam["lens_mm"]
    data.sensor_width = cam["sensor_width_mm"]
    data.sensor_height = cam["sensor_height_mm"]
    data.sensor_fit = cam["sensor_fit"]
    data.shift_x = cam["shift_x"]
    data.shift_y = cam["shift_y"]
    data.clip_start = 1e-3  # the scene is centimetres across, close to the lens
    camera = bpy.data.objects.new("camera", data)
    camera.matrix_world = Matrix(cam["matrix_world"])
    scene.collection.objects.link(camera)
    scene.camera = camera

    world = bpy.data.worlds.new("backdrop")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.75, 0.75, 0.75, 1)
    scene.world = world
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 3.0
    sun_object = bpy.data.objects.new("sun", sun)
    sun_object.rotation_euler = (0.6, 0.2, 0.3)
    scene.collection.objects.link(sun_object)

    if spec["ground_height"] is not None:
        bpy.ops.mesh.primitive_plane_add(size=100.0, location=(0.0, 0.0, spec["ground_height"]))
        bpy.context.active_object.data.materials.append(principled("floor", (0.35, 0.35, 0.35), 0.8))
    if spec["solids"]:
        add_mesh(scene, "container", spec["solids"], principled("ceramic", (0.8, 0.78, 0.72), 0.4))
    return scene


def render(scene, path):
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)


def render_liquid(scene, frames, key, material, seen_by_camera_only=False):
    """Renders each frame's liquid mesh with `material` into frame[key], but for images already there.
    Seen by the camera only, it casts no light or reflection on the solids: they stay black."""
    for frame in frames:
        if key not in frame or os.path.exists(frame[key]):
            continue
        liquid = add_mesh(scene, "liquid", frame["mesh"], material)
        if seen_by_camera_only:
            for ray in ("diffuse", "glossy", "transmission", "volume_scatter", "shadow"):
                setattr(liquid, "visible_" + ray, False)
        render(scene, frame[key])
        mesh = liquid.data
        bpy.data.objects.remove(liquid)
        bpy.data.meshes.remove(mesh)


def glowing_white():
    material = bpy.data.materials.new("liquid alone")
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    material.node_tree.links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    return material


def main():
    spec_file = sys.argv[sys.argv.index("--") + 1]
    with open(spec_file, encoding="utf-8") as fh:
        spec = json.load(fh)
    scene = set_up(spec)
    # An image already there was kept by the engine from a cancelled synth of the same simulation.
    if not os.path.exists(spec["clean_plate"]):
        render(scene, spec["clean_plate"])
    render_liquid(scene, spec["frames"], "image", principled("honey", (0.12, 0.05, 0.01), 0.6))
    bpy.data.objects.remove(bpy.data.objects["sun"])
    scene.world.node_tree.nodes["Background"].inputs[0].default_value = (0.0, 0.0, 0.0, 1.0)
    render_liquid(scene, spec["frames"], "mask_image", glowing_white(), seen_by_camera_only=True)


main()

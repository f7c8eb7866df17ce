"""Geometry of the parametric cup (a cylinder cup with a hole in its bottom) and the result import."""

import glob
import math
import os
import re

import bpy


def cup_profile(inner_radius, depth, wall, bottom, hole_radius):
    """Closed (r, z) profile of the cup's cross-section; origin at the centre of the outer bottom face."""
    outer = inner_radius + wall
    height = bottom + depth
    return [(hole_radius, 0.0), (outer, 0.0), (outer, height), (inner_radius, height),
            (inner_radius, bottom), (hole_radius, bottom)]


def revolve(profile, segments=48):
    """Vertices and faces of a closed (r, z) profile revolved about Z (r = 0 collapses to the axis)."""
    verts, rings = [], []
    for r, z in profile:
        if r <= 0.0:
            rings.append([len(verts)] * segments)
            verts.append((0.0, 0.0, z))
            continue
        ring = []
        for k in range(segments):
            a = 2.0 * math.pi * k / segments
            ring.append(len(verts))
            verts.append((r * math.cos(a), r * math.sin(a), z))
        rings.append(ring)
    faces = []
    n = len(profile)
    for i in range(n):
        a, b = rings[i], rings[(i + 1) % n]
        if profile[i][0] <= 0.0 and profile[(i + 1) % n][0] <= 0.0:
            continue
        for k in range(segments):
            k1 = (k + 1) % segments
            quad = [a[k], a[k1], b[k1], b[k]]
            unique = []
            for v in quad:
                if v not in unique:
                    unique.append(v)
            if len(unique) >= 3:
                faces.append(unique)
    return verts, faces


def build_cup_mesh(mesh, settings, segments=48):
    verts, faces = revolve(cup_profile(settings.cup_inner_radius, settings.cup_height, settings.cup_wall,
                                       settings.cup_bottom, settings.cup_hole_radius), segments)
    mesh.clear_geometry()
    mesh.from_pydata(verts, [], faces)
    mesh.validate()
    mesh.update()
    for poly in mesh.polygons:
        poly.use_smooth = False
    return mesh


def rebuild_cup(obj):
    if obj is not None and obj.type == 'MESH' and obj.viscoscope.role == 'CUP':
        build_cup_mesh(obj.data, obj.viscoscope)


def frame_files(directory, prefix="frame_", ext=".vdb"):
    """Sorted (number, path) of DIR/<prefix>NNNNN<ext>."""
    pattern = re.compile(re.escape(prefix) + r"(\d+)" + re.escape(ext) + "$")
    found = []
    for path in glob.glob(os.path.join(glob.escape(directory), prefix + "*" + ext)):
        m = pattern.search(os.path.basename(path))
        if m:
            found.append((int(m.group(1)), path))
    return sorted(found)


def import_vdb_sequence(context, directory, name="Viscoscope Liquid", material=None, grid_name="surface"):
    """DIR/frame_*.vdb → a Volume object (a sequence starting at the scene's start frame) and a mesh
    object whose Volume to Mesh modifier turns the level set into the renderable surface.

    Returns the mesh object; the Volume object is ``mesh_obj.modifiers[0].object``.
    """
    files = frame_files(directory)
    if not files:
        raise FileNotFoundError("no frame_*.vdb files in %s" % directory)
    first_number, first_path = files[0]
    volume = bpy.data.volumes.new(name + " Fields")
    volume.filepath = first_path
    if len(files) > 1:
        volume.is_sequence = True
        volume.frame_duration = files[-1][0] - first_number + 1
        volume.frame_start = context.scene.frame_start
        volume.frame_offset = first_number - 1
        volume.sequence_mode = 'EXTEND'
    vol_obj = bpy.data.objects.new(name + " Fields", volume)
    vol_obj.display_type = 'BOUNDS'
    vol_obj.hide_render = True
    context.scene.collection.objects.link(vol_obj)

    mesh_obj = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    context.scene.collection.objects.link(mesh_obj)
    mod = mesh_obj.modifiers.new("Viscoscope Surface", 'VOLUME_TO_MESH')
    mod.object = vol_obj
    mod.grid_name = grid_name
    mod.threshold = 0.0
    mod.resolution_mode = 'GRID'
    mod.use_smooth_shade = True
    if material is not None:
        mesh_obj.data.materials.append(material)
    return mesh_obj

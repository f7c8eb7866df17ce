"""Bake Mantaflow's counterpart of the capture-cup sample scene, for solver_vs_mantaflow.py.

Run by Blender, not by pytest:

    blender -b --factory-startup --python tests/bench/mantaflow_bake.py -- \
        --res 64 --frames 10 --viscosity-value 0.088 --cache /tmp/cache

The scene mirrors sample_scenes/capture_cup.json (SI units, unit scale 1 = metres):
a 0.18 m liquid domain whose closed bottom border is the ground, a cup (inner radius 0.043 m,
wall 0.006 m, bottom 0.005 m with a 0.009 m radius hole, outer bottom at z = 0.10 m, inner depth
0.05 m) as a COLLISION effector, and 170 cm³ of liquid resting on the cup's inner bottom as a
GEOMETRY liquid flow.  Only the bake is timed.  The last stdout line starting with
"MANTAFLOW_RESULT " carries a JSON record for the caller.
"""

import argparse
import json
import math
import os
import sys
import time

import bmesh
import bpy

# Geometry of sample_scenes/capture_cup.json, in metres.
DOMAIN_MIN = (-0.09, -0.09, 0.0)
DOMAIN_MAX = (0.09, 0.09, 0.18)
CUP_Z = 0.10
CUP_INNER_R = 0.043
CUP_WALL = 0.006
CUP_BOTTOM = 0.005
CUP_HOLE_R = 0.009
CUP_DEPTH = 0.05
LIQUID_VOLUME = 170e-6
FPS = 30
SEGMENTS = 64


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="mantaflow_bake.py")
    p.add_argument("--res", type=int, required=True, help="domain resolution_max")
    p.add_argument("--frames", type=int, required=True, help="frames to bake (1..F)")
    p.add_argument("--viscosity-value", type=float, required=True,
                   help="Mantaflow viscosity_value (nu * 0.4 / L^2, see DESIGN.md)")
    p.add_argument("--cache", required=True, help="absolute cache directory")
    p.add_argument("--no-viscosity", action="store_true", help="leave use_viscosity off")
    return p.parse_args(argv)


def revolve(name, profile, segments=SEGMENTS):
    """A closed mesh: the (r, z) polygon `profile` swept around the z axis."""
    bm = bmesh.new()
    rings = []
    for i in range(segments):
        a = 2 * math.pi * i / segments
        c, s = math.cos(a), math.sin(a)
        rings.append([bm.verts.new((r * c, r * s, z)) for r, z in profile])
    n = len(profile)
    for i in range(segments):
        a, b = rings[i], rings[(i + 1) % segments]
        for j in range(n):
            k = (j + 1) % n
            bm.faces.new((a[j], b[j], b[k], a[k]))
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces[:])
    return to_object(name, bm)


def disc_cylinder(name, radius, z0, z1, segments=SEGMENTS):
    bm = bmesh.new()
    bmesh.ops.create_cone(bm, cap_ends=True, cap_tris=False, segments=segments,
                          radius1=radius, radius2=radius, depth=z1 - z0)
    bmesh.ops.translate(bm, verts=bm.verts[:], vec=(0.0, 0.0, 0.5 * (z0 + z1)))
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces[:])
    return to_object(name, bm)


def box(name, lo, hi):
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    for v in bm.verts:
        v.co = [lo[i] + (v.co[i] + 0.5) * (hi[i] - lo[i]) for i in range(3)]
    return to_object(name, bm)


def to_object(name, bm):
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def main():
    args = parse_args()
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)

    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start = 1
    scene.frame_end = args.frames
    scene.use_gravity = True
    scene.gravity = (0.0, 0.0, -9.81)

    # Cup: outer bottom at CUP_Z, inner bottom at CUP_Z + CUP_BOTTOM, rim CUP_DEPTH above that.
    z_inner = CUP_Z + CUP_BOTTOM
    z_top = z_inner + CUP_DEPTH
    r_out = CUP_INNER_R + CUP_WALL
    cup = revolve("Cup", [(CUP_HOLE_R, CUP_Z), (r_out, CUP_Z), (r_out, z_top),
                          (CUP_INNER_R, z_top), (CUP_INNER_R, z_inner), (CUP_HOLE_R, z_inner)])
    fill_h = LIQUID_VOLUME / (math.pi * CUP_INNER_R ** 2)
    liquid = disc_cylinder("Liquid", CUP_INNER_R, z_inner, z_inner + fill_h)
    domain = box("Domain", DOMAIN_MIN, DOMAIN_MAX)

    mod = cup.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "EFFECTOR"
    mod.effector_settings.effector_type = "COLLISION"

    mod = liquid.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "FLOW"
    mod.flow_settings.flow_type = "LIQUID"
    mod.flow_settings.flow_behavior = "GEOMETRY"
    mod.flow_settings.flow_source = "MESH"
    liquid.hide_render = True

    mod = domain.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "DOMAIN"
    ds = mod.domain_settings
    ds.domain_type = "LIQUID"
    ds.resolution_max = args.res
    ds.use_viscosity = not args.no_viscosity
    ds.viscosity_value = args.viscosity_value
    ds.use_mesh = False
    ds.use_collision_border_bottom = True  # the ground
    os.makedirs(args.cache, exist_ok=True)
    ds.cache_directory = os.path.abspath(args.cache)
    ds.cache_type = "ALL"
    ds.cache_frame_start = 1
    ds.cache_frame_end = args.frames
    # Everything else (CFL 4, 1..4 steps per frame, FLIP particles) stays at Blender's defaults.

    for obj in (cup, liquid, domain):
        obj.select_set(obj is domain)
    bpy.context.view_layer.objects.active = domain
    bpy.context.view_layer.update()

    with bpy.context.temp_override(active_object=domain, object=domain, selected_objects=[domain],
                                   selected_editable_objects=[domain], scene=scene):
        t0 = time.perf_counter()
        result = bpy.ops.fluid.bake_all()
        bake_seconds = time.perf_counter() - t0

    cache_files = 0
    for _root, _dirs, files in os.walk(args.cache):
        cache_files += len(files)
    data_dir = os.path.join(args.cache, "data")
    data_files = len(os.listdir(data_dir)) if os.path.isdir(data_dir) else 0
    record = {
        "res": args.res, "frames": args.frames, "viscosity_value": args.viscosity_value,
        "use_viscosity": ds.use_viscosity, "bake_seconds": bake_seconds,
        "operator_result": sorted(result), "cache_files": cache_files, "data_files": data_files,
        "cfl_condition": ds.cfl_condition, "timesteps_min": ds.timesteps_min,
        "timesteps_max": ds.timesteps_max, "blender": bpy.app.version_string,
    }
    print("MANTAFLOW_RESULT " + json.dumps(record), flush=True)


if __name__ == "__main__":
    main()

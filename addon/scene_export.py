"""Blender scene → the engine's scene JSON ("viscoscope.scene" version 1), in SI units.

Blender lengths are multiplied by scene.unit_settings.scale_length (metres per Blender unit) and
volumes by its cube, here and nowhere else. Objects take part through their Viscoscope role
(object.viscoscope.role). Every problem is reported as one line naming the object and field.
"""

import json
import os

import bpy

from . import schema, units
from .atomic_files import written_atomically

SCENE_FORMAT = "viscoscope.scene"
SCENE_VERSION = 1
CAMERA_FORMAT = "viscoscope.blender_camera"
CAMERA_VERSION = 1

MODEL_TYPES = {'NEWTONIAN': "newtonian", 'POWER_LAW': "power_law", 'CARREAU': "carreau",
               'HERSCHEL_BULKLEY': "herschel_bulkley"}


class ExportError(ValueError):
    """One-line reason why the scene cannot be exported."""


def _world_bounds(obj):
    corners = [obj.matrix_world @ _vec(c) for c in obj.bound_box]
    lo = [min(c[i] for c in corners) for i in range(3)]
    hi = [max(c[i] for c in corners) for i in range(3)]
    return lo, hi


def _vec(seq):
    from mathutils import Vector
    return Vector(seq)


def _clean(value):
    """Blender stores single precision: write 0.043, not 0.0430000014603138."""
    return float("%.7g" % value)


def _finite_vec(name, vec):
    out = []
    for i, c in enumerate(vec):
        try:
            out.append(_clean(units.check_finite("%s[%d]" % (name, i), c)))
        except units.UnitError as exc:
            raise ExportError(str(exc)) from exc
    return out


def _field(name, value, minimum=None, positive=False):
    try:
        return _clean(units.check_finite(name, value, minimum=minimum, strictly_positive=positive))
    except units.UnitError as exc:
        raise ExportError(str(exc)) from exc


def _declared(name, value):
    """A material parameter, checked against the engine's declared bounds before the engine sees it."""
    value = _field("material " + name, value)
    lower, upper = schema.bounds(name)
    if not lower <= value <= upper:
        raise ExportError("material %s: %g %s is outside [%g, %g]"
                          % (name, value, schema.PARAMETERS[name]["unit"], lower, upper))
    return value


def _uniform_scale(obj):
    s = obj.matrix_world.to_scale()
    if max(s) - min(s) > 1e-6 * max(abs(max(s)), 1e-12):
        raise ExportError("'%s' must be scaled uniformly to be exported as a cup, scale is %s"
                          % (obj.name, tuple(round(c, 6) for c in s)))
    return s[0]


def cup_solid(obj, scale_length):
    vs = obj.viscoscope
    up = obj.matrix_world.to_3x3().normalized() @ _vec((0.0, 0.0, 1.0))
    if up.z < 1.0 - 1e-6:
        raise ExportError("cup '%s' must stand upright (local Z along world Z)" % obj.name)
    k = _uniform_scale(obj) * scale_length
    position = _finite_vec("cup '%s' position" % obj.name, units.vec_to_metres(obj.matrix_world.translation, scale_length))
    inner = _field("cup '%s' inner_radius" % obj.name, vs.cup_inner_radius * k, positive=True)
    hole = _field("cup '%s' hole_radius" % obj.name, vs.cup_hole_radius * k, minimum=0.0)
    if hole >= inner:
        raise ExportError("cup '%s' hole_radius (%g m) must be smaller than inner_radius (%g m)" % (obj.name, hole, inner))
    return {"type": "cup", "position": position, "inner_radius": inner,
            "height": _field("cup '%s' height" % obj.name, vs.cup_height * k, positive=True),
            "wall_thickness": _field("cup '%s' wall_thickness" % obj.name, vs.cup_wall * k, positive=True),
            "bottom_thickness": _field("cup '%s' bottom_thickness" % obj.name, vs.cup_bottom * k, positive=True),
            "hole_radius": hole}


def write_obj(obj, path, depsgraph, scale_length):
    """Write the evaluated mesh of obj in world space, metres, as a triangulated OBJ."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        if not mesh.polygons:
            raise ExportError("solid '%s' has no faces" % obj.name)
        mesh.calc_loop_triangles()
        mw = obj.matrix_world
        with written_atomically(path) as fh:
            fh.write("# Viscoscope solid '%s', metres, world space, Z up\n" % obj.name.replace("\n", " "))
            for v in mesh.vertices:
                p = mw @ v.co
                fh.write("v %.9g %.9g %.9g\n" % tuple(c * scale_length for c in p))
            for tri in mesh.loop_triangles:
                a, b, c = tri.vertices
                fh.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
    finally:
        evaluated.to_mesh_clear()


def _safe_filename(name):
    keep = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)
    return keep.strip("._") or "solid"


def material_dict(fluid):
    model = {"type": MODEL_TYPES[fluid.model]}
    # Each model's parameters as the engine declares them (schema.py), minus the regularization caps
    # the panel does not show (eta_min, eta_max keep the engine's defaults).
    for name, declaration in schema.PARAMETERS.items():
        if declaration["home"] == "material.model" and model["type"] in declaration["types"] and hasattr(fluid, name):
            model[name] = _declared(name, getattr(fluid, name))
    material = {name: _declared(name, getattr(fluid, name))
                for name, declaration in schema.PARAMETERS.items() if declaration["home"] == "material"}
    material["model"] = model
    return material


def build_scene(scene, scene_dir, objects=None, depsgraph=None, fluid=None):
    """The scene dict; mesh solids are written as OBJ files into scene_dir. `fluid` (default the
    scene's own Fluid Material) is the material: another run of one liquid takes the first run's."""
    vs = scene.viscoscope
    if bpy.context.scene == scene:
        bpy.context.view_layer.update()  # matrix_world of objects moved by scripts
    scale_length = _field("unit scale", scene.unit_settings.scale_length, positive=True)
    objects = list(scene.objects if objects is None else objects)
    by_role = {}
    for obj in objects:
        by_role.setdefault(obj.viscoscope.role, []).append(obj)

    domains = by_role.get('DOMAIN', [])
    if len(domains) != 1:
        raise ExportError("the scene needs exactly one object with Viscoscope role 'Domain', found %d" % len(domains))
    lo, hi = _world_bounds(domains[0])
    dmin = _finite_vec("domain min", units.vec_to_metres(lo, scale_length))
    dmax = _finite_vec("domain max", units.vec_to_metres(hi, scale_length))
    for i, axis in enumerate("xyz"):
        if not dmax[i] > dmin[i]:
            raise ExportError("domain '%s' is flat along %s" % (domains[0].name, axis))

    solids, cup_index = [], {}
    for obj in by_role.get('GROUND', []):
        solids.append({"type": "ground",
                       "height": _field("ground '%s' height" % obj.name, obj.matrix_world.translation.z * scale_length)})
    for obj in by_role.get('CUP', []):
        cup_index[obj.name] = len(solids)
        solids.append(dict(cup_solid(obj, scale_length), transparent=obj.viscoscope.transparent))
    mesh_solids = [o for o in by_role.get('SOLID', [])]
    if mesh_solids:
        depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
        os.makedirs(scene_dir, exist_ok=True)
        used = set()
        for obj in mesh_solids:
            if obj.type not in {'MESH', 'CURVE', 'SURFACE', 'META', 'FONT'}:
                raise ExportError("solid '%s' is a %s, not something with a surface" % (obj.name, obj.type.lower()))
            fname = "solid_" + _safe_filename(obj.name)
            while fname in used:
                fname += "_"
            used.add(fname)
            write_obj(obj, os.path.join(scene_dir, fname + ".obj"), depsgraph, scale_length)
            solids.append({"type": "mesh", "path": fname + ".obj", "transparent": obj.viscoscope.transparent})

    liquids = []
    for obj in by_role.get('LIQUID', []):
        llo, lhi = _world_bounds(obj)
        liquids.append({"type": "box",
                        "min": _finite_vec("liquid '%s' min" % obj.name, units.vec_to_metres(llo, scale_length)),
                        "max": _finite_vec("liquid '%s' max" % obj.name, units.vec_to_metres(lhi, scale_length))})
    if vs.cup is not None and vs.fill_volume > 0.0:
        if vs.cup.name not in cup_index:
            raise ExportError("container cup '%s' is not in the exported objects" % vs.cup.name)
        liquids.append({"type": "cup_fill", "cup": cup_index[vs.cup.name],
                        "volume": _field("fluid volume", vs.fill_volume * scale_length ** 3, positive=True)})
    for obj in by_role.get('EMITTER', []):
        ov = obj.viscoscope
        k = _uniform_scale(obj) * scale_length
        normal = (obj.matrix_world.to_3x3().normalized() @ _vec((0.0, 0.0, 1.0))).normalized()
        start = _field("emitter '%s' start" % obj.name, ov.emitter_start, minimum=0.0)
        end = _field("emitter '%s' end" % obj.name, ov.emitter_end, minimum=0.0)
        if end < start:
            raise ExportError("emitter '%s' ends (%g s) before it starts (%g s)" % (obj.name, end, start))
        liquids.append({"type": "emitter",
                        "center": _finite_vec("emitter '%s' center" % obj.name,
                                              units.vec_to_metres(obj.matrix_world.translation, scale_length)),
                        "normal": _finite_vec("emitter '%s' normal" % obj.name, normal),
                        "radius": _field("emitter '%s' radius" % obj.name, ov.emitter_radius * k, positive=True),
                        "flux": _field("emitter '%s' flux" % obj.name, ov.emitter_flux * scale_length ** 3, minimum=0.0),
                        "start": start, "end": end})
    if not liquids:
        raise ExportError("no liquid: give an object the role 'Liquid' or 'Emitter', or fill the cup")

    fps = _field("frame rate", scene.render.fps / scene.render.fps_base, positive=True)
    gravity = _finite_vec("gravity", scene.gravity if scene.use_gravity else (0.0, 0.0, 0.0))
    return {
        "format": SCENE_FORMAT, "version": SCENE_VERSION,
        "domain": {"min": dmin, "max": dmax, "resolution": int(vs.sim_resolution),
                   "periodic": [False, False, False]},
        "solids": solids,
        "liquids": liquids,
        "material": material_dict(fluid or vs.fluid),
        "gravity": gravity,  # m/s²: physical, not rescaled with the unit scale
        "fps": fps,
        "frames": int(vs.sim_frames),
        "seed": int(vs.sim_seed),
        # No "solver": the engine's defaults (scene.h), which Table 1 and the time budget were measured with.
        "output": {"particles": True, "vdb": True, "mesh": False},
    }


def export_material(fluid, path):
    """Write a scene that holds only the fluid's material (in a unit box of liquid), for the engine
    to answer questions about the material alone (`viscoscope viscosity`)."""
    data = {"format": SCENE_FORMAT, "version": SCENE_VERSION,
            "domain": {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0], "resolution": 8},
            "liquids": [{"type": "box", "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.5]}],
            "material": material_dict(fluid), "fps": 24.0, "frames": 1}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with written_atomically(path) as fh:
        json.dump(data, fh, indent=1, allow_nan=False)


def export_scene(scene, path, objects=None, fluid=None):
    """Write the scene JSON to path and return the dict."""
    data = build_scene(scene, os.path.dirname(os.path.abspath(path)), objects, fluid=fluid)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with written_atomically(path) as fh:
        json.dump(data, fh, indent=1, allow_nan=False)
    return data


def camera_dict(cam_obj, scene):
    """The "viscoscope.blender_camera" JSON for a camera object (matrix_world in metres)."""
    if cam_obj is None or cam_obj.type != 'CAMERA':
        raise ExportError("no camera: choose a camera object")
    cam = cam_obj.data
    if cam.type != 'PERSP':
        raise ExportError("camera '%s' must be perspective, it is %s" % (cam_obj.name, cam.type.lower()))
    scale_length = scene.unit_settings.scale_length
    m = cam_obj.matrix_world
    matrix = []
    for i in range(4):
        row = []
        for j in range(4):
            value = m[i][j]
            if j < 3 and i < 3:
                value = value / m.col[j].xyz.length
            elif j == 3 and i < 3:
                value = value * scale_length
            row.append(_field("camera matrix_world", value))
        matrix.append(row)
    r = scene.render
    return {"format": CAMERA_FORMAT, "version": CAMERA_VERSION,
            "lens_mm": _field("camera lens", cam.lens, positive=True),
            "sensor_width_mm": _field("camera sensor_width", cam.sensor_width, positive=True),
            "sensor_height_mm": _field("camera sensor_height", cam.sensor_height, positive=True),
            "sensor_fit": cam.sensor_fit,
            "shift_x": _field("camera shift_x", cam.shift_x), "shift_y": _field("camera shift_y", cam.shift_y),
            "resolution_x": r.resolution_x, "resolution_y": r.resolution_y,
            "resolution_percentage": r.resolution_percentage,
            "pixel_aspect_x": _field("render pixel_aspect_x", r.pixel_aspect_x, positive=True),
            "pixel_aspect_y": _field("render pixel_aspect_y", r.pixel_aspect_y, positive=True),
            "matrix_world": matrix}


def export_camera(cam_obj, scene, path):
    data = camera_dict(cam_obj, scene)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with written_atomically(path) as fh:
        json.dump(data, fh, indent=1, allow_nan=False)
    return data


def work_dir(scene):
    """Absolute work folder: the setting, relative to the .blend; for an unsaved file, under the
    system temp folder like Blender's own fluid caches (not bpy.app.tempdir, which is deleted when
    Blender quits and would orphan imported .vdb sequences)."""
    raw = scene.viscoscope.work_dir or "//viscoscope"
    if raw.startswith("//") and not bpy.data.filepath:
        import tempfile
        return os.path.join(tempfile.gettempdir(), raw[2:] or "viscoscope")
    return os.path.abspath(bpy.path.abspath(raw))

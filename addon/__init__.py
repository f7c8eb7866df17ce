"""Viscoscope: identify a liquid's viscosity from a phone video and use it as a fluid material.

The version below is the single source of truth: blender_manifest.toml must carry the same one
(scripts/build_addon_zip.py refuses to build and a test fails when they differ).
"""

bl_info = {
    "name": "Viscoscope",
    "author": "Viscoscope developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "3D Viewport > Sidebar > Viscoscope",
    "description": "Identify viscosity from video and carry it into fluid material presets",
    "doc_url": "",
    "category": "Physics",
}

import bpy

from . import operators, presets, prefs, props, ui
from .operators import runner

_classes = presets.classes + operators.classes + ui.classes


def version_string():
    return ".".join(str(v) for v in bl_info["version"])


def register():
    prefs.register()
    props.register()
    for cls in _classes:
        bpy.utils.register_class(cls)


def unregister():
    from . import engine
    for kind in list(runner.ACTIVE):
        runner.cancel(kind)
    engine.terminate_all()
    runner.ACTIVE.clear()
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    props.unregister()
    prefs.unregister()

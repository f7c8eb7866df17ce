"""Add-on preferences: engine location and threads (found via __package__, so this works as a
legacy add-on and as a bl_ext.* extension)."""

import os

import bpy
from bpy.props import IntProperty, StringProperty

from . import engine

ADDON_ID = __package__
ADDON_DIR = os.path.dirname(os.path.abspath(__file__))


class ViscoscopePreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    engine_path: StringProperty(name="Engine", subtype='FILE_PATH', default="",
                                description="The viscoscope executable; empty to find it automatically "
                                            "(bundled, $VISCOSCOPE_ENGINE, or <repo>/build/bin)")
    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="Engine threads; 0 uses every core")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "engine_path")
        layout.prop(self, "threads")
        try:
            path = find_engine(context)
        except engine.EngineError as exc:
            layout.label(text=str(exc), icon='ERROR')
            return
        found = engine.engine_version(path)
        if found == addon_version():
            layout.label(text="Using %s (version %s)" % (path, found), icon='CHECKMARK')
        else:
            layout.label(text="Engine %s is version %s, the add-on is %s" % (path, found or "?", addon_version()),
                         icon='ERROR')


def addon_version():
    import sys
    return ".".join(str(v) for v in sys.modules[ADDON_ID].bl_info["version"])


def get(context=None):
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


def find_engine(context=None):
    prefs = get(context)
    path = bpy.path.abspath(prefs.engine_path) if prefs is not None and prefs.engine_path else ""
    return engine.find_engine(path, ADDON_DIR)


def threads(context=None):
    prefs = get(context)
    return prefs.threads if prefs is not None else 0


def register():
    bpy.utils.register_class(ViscoscopePreferences)


def unregister():
    bpy.utils.unregister_class(ViscoscopePreferences)

"""Viscoscope fluid material presets, in Blender's own style (a preset menu in the panel header).
Presets are stored in the user's config (scripts/presets/viscoscope/fluid), never inside the
add-on folder.

A preset file reads like one of Blender's own Python presets, headed by the name it was saved under:

    'Clover Honey'
    import bpy
    fluid = bpy.context.scene.viscoscope.fluid

    fluid.viscosity = 8.0
    ...

The menu shows each preset under that name. Saving under the same name again overwrites it; another
name that makes the same file name gets a numbered file (Preset_2.py). File names keep only letters
and digits of any script, "-" and "_" (see preset_filename).

A Blender preset is a Python file that Blender executes. write_preset writes the name and every
value with repr(), so no preset name or value can inject code; tests/blender/test_presets.py checks it.
"""

import ast
import glob
import os
import re

import bpy
from bl_operators.presets import AddPresetBase
from bl_ui.utils import PresetPanel

PRESET_SUBDIR = os.path.join("viscoscope", "fluid")

FLUID_FIELDS = ("description", "viscosity", "density", "surface_tension", "slip_length", "model",
                "consistency", "flow_index", "eta_infinity", "relaxation_time", "yield_stress", "color", "roughness",
                "transmission")

# The lines Blender's presets bind the fluid with.
BOILERPLATE = ("import bpy", "fluid = bpy.context.scene.viscoscope.fluid")


def user_preset_dir(create=True):
    return bpy.utils.user_resource('SCRIPTS', path=os.path.join("presets", PRESET_SUBDIR), create=create)


def preset_filename(name):
    """Letters and digits of any script, "-" and "_" only (no path separator, dot or control
    character), never empty, at most 60 characters: with a number and ".py", 4-byte letters
    stay within the 255 bytes file systems allow."""
    cleaned = re.sub(r"[^\w-]+", "_", name.strip()).strip("_")
    return cleaned[:60].strip("_") or "Preset"


def preset_name(path):
    """The name a preset was saved under (its file's first line); for a preset without one, the name
    Blender's menus give its file."""
    try:
        with open(path, encoding="utf-8") as fh:
            name = ast.get_docstring(ast.parse(fh.read()), clean=False)
    except (OSError, ValueError, SyntaxError):  # a broken file still gets a menu entry, to report on
        name = None
    return name or bpy.path.display_name(path, title_case=False)


def find_preset(name):
    """The user's preset file saved under `name`, or None."""
    paths = sorted(glob.glob(os.path.join(glob.escape(user_preset_dir()), "*.py")))
    return next((path for path in paths if preset_name(path) == name), None)


def new_preset_path(name):
    """A file for a new preset: its name's file name, numbered when another preset has that one."""
    folder, stem = user_preset_dir(), preset_filename(name)
    path = os.path.join(folder, stem + ".py")
    number = 2
    while os.path.exists(path):
        path = os.path.join(folder, "%s_%d.py" % (stem, number))
        number += 1
    return path


def _is_vector(prop):
    return prop.type == 'FLOAT' and prop.is_array


def fluid_values(fluid):
    """{field: value} of every preset field of `fluid`."""
    rna = fluid.bl_rna.properties
    return {field: getattr(fluid, field)[:] if _is_vector(rna[field]) else getattr(fluid, field)
            for field in FLUID_FIELDS}


def write_preset(path, name, values):
    lines = [repr(name), *BOILERPLATE, ""] + ["fluid.%s = %r" % item for item in values.items()]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


def path_menu_labelled(self, searchpaths, operator, **kwargs):
    """Menu.path_menu, each preset labelled with the name it was saved under (Blender's preset
    menus label files by their file names, which keep only some characters)."""
    kwargs["display_name"] = preset_name
    bpy.types.Menu.path_menu(self, searchpaths, operator, **kwargs)


class VISCOSCOPE_MT_fluid_presets(bpy.types.Menu):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"
    preset_add_operator = "viscoscope.fluid_preset_add"
    path_menu = path_menu_labelled
    draw = bpy.types.Menu.draw_preset


class VISCOSCOPE_PT_fluid_presets(PresetPanel, bpy.types.Panel):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"
    preset_add_operator = "viscoscope.fluid_preset_add"
    path_menu = path_menu_labelled


class VISCOSCOPE_OT_fluid_preset_add(AddPresetBase, bpy.types.Operator):
    """Save the fluid material (η, ρ, σ, model parameters, render colour) as a preset in your user config"""
    bl_idname = "viscoscope.fluid_preset_add"
    bl_label = "Save Fluid Preset"

    # AddPresetBase gives the name/remove properties the preset menu's buttons set and the dialog;
    # finding, writing and removing the file are ours, since a preset's file is found by its name.

    # AddPresetBase's name has maxlen=64, which cuts bytes: a longer name in Cyrillic, say, ends
    # mid-character and cannot be read back. The file name is cut (by characters) in preset_filename.
    name: bpy.props.StringProperty(name="Name", description="Name of the preset", options={'SKIP_SAVE'})

    def check(self, _context):
        return False  # keep the name as typed (AddPresetBase's would turn it into a file name)

    def execute(self, context):
        if self.remove_name or self.remove_active:
            name = self.name if self.remove_name else VISCOSCOPE_MT_fluid_presets.bl_label
            path = find_preset(name)
            if path is None:
                self.report({'ERROR'}, "No preset named %r among your presets" % name)
                return {'CANCELLED'}
            os.remove(path)
            return {'FINISHED'}
        name = self.name.strip()
        if not name:
            return {'FINISHED'}  # as AddPresetBase: the dialog closed without a name saves nothing
        path = find_preset(name) or new_preset_path(name)
        write_preset(path, name, fluid_values(context.scene.viscoscope.fluid))
        VISCOSCOPE_MT_fluid_presets.bl_label = name
        wm = context.window_manager
        if wm.preset_name == name:  # as AddPresetBase: the panel's name field is ready for the next one
            wm.preset_name = "New Preset"
        return {'FINISHED'}


classes = (VISCOSCOPE_MT_fluid_presets, VISCOSCOPE_PT_fluid_presets, VISCOSCOPE_OT_fluid_preset_add)

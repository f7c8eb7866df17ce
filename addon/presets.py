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

A preset is never executed. Loading parses it with ast, reads each value with ast.literal_eval and
checks every one (a preset field, the property's type, finite, within the property's hard bounds,
an item of its enum, text Blender can hold) before it applies any, so a damaged, hand-edited or
newer preset changes nothing and says in one line which file and field are wrong; a file larger
than any preset or nested deeper than ast goes is refused the same way. Saving refuses what loading
would (a NaN) and writes the name and every value with repr(), whole or not at all. So no preset
name or value can inject code; tests/blender/test_presets.py checks it, with a mutation corpus.
"""

import ast
import glob
import math
import os
import re

import bpy
from bl_operators.presets import AddPresetBase
from bl_ui.utils import PresetPanel

from . import props, schema
from .atomic_files import written_atomically

PRESET_SUBDIR = os.path.join("viscoscope", "fluid")

# Every material parameter the engine declares (schema.py) that the fluid group holds, and around
# them the fields that are not the engine's parameters. Loading applies them in this order:
# identified_from after the viscosity, setting which clears it.
MATERIAL_PARAMETERS = tuple(name for name, declaration in schema.PARAMETERS.items()
                            if declaration["home"] in ("material", "material.model")
                            and name in props.ViscoscopeFluid.__annotations__)
FLUID_FIELDS = (("description", "model") + MATERIAL_PARAMETERS
                + ("color", "roughness", "transmission", "identified_from"))

# The lines Blender's presets bind the fluid with: a preset may have them, nothing else but values.
BOILERPLATE = ("import bpy", "fluid = bpy.context.scene.viscoscope.fluid")

# A saved preset is a few hundred bytes, a few KiB with a long description. A larger file is no
# preset and is not parsed: parsing time and the text a refusal shows stay bounded whatever it holds.
MAX_PRESET_BYTES = 64 * 1024


class PresetError(ValueError):
    """A preset that cannot be saved or loaded; the message names the field or line that is wrong."""


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
        name = ast.get_docstring(_parsed(path), clean=False)
    except PresetError:  # a broken file still gets a menu entry, to report on
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


def _excerpt(text, limit=60):
    """`text`, cut to `limit` characters: a refusal is one line the panel can show."""
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _shown(value):
    return _excerpt(repr(value))


def _blender_can_hold(text):
    """Blender holds text as UTF-8 up to its first NUL: other text would be stored cut short, or
    refused by the assignment after the fields before it were applied."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:  # a lone surrogate, which "\udc80" in a file makes
        return False
    return "\0" not in text


def _fluid_property(field):
    if field not in FLUID_FIELDS:
        raise PresetError("%s: not a field of a fluid preset (one from a newer Viscoscope?)" % _excerpt(field))
    return props.ViscoscopeFluid.bl_rna.properties[field]


def _checked_number(field, number, prop):
    if isinstance(number, bool) or not isinstance(number, (int, float)):
        raise PresetError("%s: %s is not a number" % (field, _shown(number)))
    if not math.isfinite(number):
        raise PresetError("%s: %s is not a finite number" % (field, _shown(number)))
    if not prop.hard_min <= number <= prop.hard_max:
        raise PresetError("%s: %g is outside %g to %g" % (field, number, prop.hard_min, prop.hard_max))
    return float(number)


def checked_value(field, value):
    """`value` as the fluid's `field` takes it, or PresetError: a preset is checked whole before
    any of it is applied, since assigning clamps out-of-range numbers silently and stores a NaN."""
    prop = _fluid_property(field)
    if prop.type == 'STRING':
        if not isinstance(value, str):
            raise PresetError("%s: %s is not text" % (field, _shown(value)))
        if not _blender_can_hold(value):
            raise PresetError("%s: %s is not text Blender can hold (a NUL or a lone surrogate)"
                              % (field, _shown(value)))
        return value
    if prop.type == 'ENUM':
        items = [item.identifier for item in prop.enum_items]
        if not isinstance(value, str) or value not in items:
            raise PresetError("%s: %s is not one of %s" % (field, _shown(value), ", ".join(items)))
        return value
    if _is_vector(prop):
        if not isinstance(value, (tuple, list)) or len(value) != prop.array_length:
            raise PresetError("%s: %s is not %d numbers" % (field, _shown(value), prop.array_length))
        return tuple(_checked_number(field, number, prop) for number in value)
    if prop.type == 'FLOAT':
        return _checked_number(field, value, prop)
    raise PresetError("%s: a preset cannot hold a %s property" % (field, prop.type))


def fluid_values(fluid):
    """{field: value} of every preset field of `fluid`, checked as a loaded preset's are."""
    rna = fluid.bl_rna.properties
    return {field: checked_value(field, getattr(fluid, field)[:] if _is_vector(rna[field]) else getattr(fluid, field))
            for field in FLUID_FIELDS}


def write_preset(path, name, values):
    """Whole or not at all: a full disk leaves the previous preset, not half of a new one."""
    lines = [repr(name), *BOILERPLATE, ""] + ["fluid.%s = %r" % item for item in values.items()]
    with written_atomically(path) as fh:
        fh.write("\n".join(lines) + "\n")


def _assigned_field(node):
    """NAME of a `fluid.NAME = ...` statement, else None."""
    if isinstance(node, ast.Assign) and len(node.targets) == 1:
        target = node.targets[0]
        if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == "fluid":
            return target.attr
    return None


def _parsed(path):
    """The syntax tree of a preset file, which is parsed, never executed; PresetError when it cannot be."""
    try:
        with open(path, "rb") as fh:
            source = fh.read(MAX_PRESET_BYTES + 1)
    except OSError as exc:
        raise PresetError("cannot be read: %s" % exc) from exc
    if len(source) > MAX_PRESET_BYTES:
        raise PresetError("larger than %d KiB, which no preset is" % (MAX_PRESET_BYTES // 1024))
    try:
        return ast.parse(source.decode("utf-8"))
    except (ValueError, SyntaxError) as exc:  # not UTF-8, a NUL byte, not Python
        raise PresetError("cannot be read: %s" % exc) from exc
    except (RecursionError, MemoryError) as exc:  # the parser's answers to deep nesting, not a lack of memory
        raise PresetError("cannot be read: nested too deeply") from exc


def _read_statement(node):
    """(field, checked value) of a `fluid.NAME = value` statement, None for a line of BOILERPLATE."""
    field = _assigned_field(node)
    if field is None:
        if ast.unparse(node) in BOILERPLATE:
            return None
        raise PresetError("line %d is not a 'fluid.NAME = value' line" % node.lineno)
    _fluid_property(field)  # an unknown field is named as such, before its value is judged
    try:
        value = ast.literal_eval(node.value)
    except (ValueError, TypeError) as exc:
        raise PresetError("%s: %s is not a plain value" % (field, _excerpt(ast.unparse(node.value)))) from exc
    return field, checked_value(field, value)


def read_preset(path):
    """{field: value} of a preset file, parsed and checked, never executed; PresetError says what is wrong."""
    tree = _parsed(path)
    body = tree.body[1:] if ast.get_docstring(tree, clean=False) is not None else tree.body
    values = {}
    for node in body:
        try:
            statement = _read_statement(node)
        except RecursionError as exc:  # ast.unparse recurses as deep as the line nests, past the parser's own limit
            raise PresetError("line %d is nested too deeply" % node.lineno) from exc
        if statement is not None:
            field, value = statement
            values[field] = value
    return values


def path_menu_labelled(self, searchpaths, operator, **kwargs):
    """Menu.path_menu, each preset labelled with the name it was saved under (Blender's preset
    menus label files by their file names, which keep only some characters)."""
    kwargs["display_name"] = preset_name
    bpy.types.Menu.path_menu(self, searchpaths, operator, **kwargs)


class VISCOSCOPE_MT_fluid_presets(bpy.types.Menu):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "viscoscope.fluid_preset_load"
    preset_add_operator = "viscoscope.fluid_preset_add"
    path_menu = path_menu_labelled
    draw = bpy.types.Menu.draw_preset


class VISCOSCOPE_PT_fluid_presets(PresetPanel, bpy.types.Panel):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "viscoscope.fluid_preset_load"
    preset_add_operator = "viscoscope.fluid_preset_add"
    path_menu = path_menu_labelled


class VISCOSCOPE_OT_fluid_preset_load(bpy.types.Operator):
    """Load this fluid preset into the Fluid Material: all of its values, or none if one is wrong"""
    bl_idname = "viscoscope.fluid_preset_load"
    bl_label = "Load Fluid Preset"
    bl_options = {'REGISTER', 'UNDO', 'INTERNAL'}

    filepath: bpy.props.StringProperty(subtype='FILE_PATH', options={'SKIP_SAVE'})

    def execute(self, context):
        try:
            values = read_preset(self.filepath)
        except PresetError as exc:
            self.report({'ERROR'}, "Preset %s not loaded: %s" % (os.path.basename(self.filepath), exc))
            return {'CANCELLED'}
        fluid = context.scene.viscoscope.fluid
        for field in FLUID_FIELDS:
            if field in values:
                setattr(fluid, field, values[field])
        # The active preset, as Blender's preset menus keep it (remove_active removes it).
        VISCOSCOPE_MT_fluid_presets.bl_label = preset_name(self.filepath)
        return {'FINISHED'}


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
        try:
            values = fluid_values(context.scene.viscoscope.fluid)
            write_preset(find_preset(name) or new_preset_path(name), name, values)
        except (PresetError, OSError) as exc:
            self.report({'ERROR'}, "Preset %r not saved: %s" % (name, exc))
            return {'CANCELLED'}
        VISCOSCOPE_MT_fluid_presets.bl_label = name
        wm = context.window_manager
        if wm.preset_name == name:  # as AddPresetBase: the panel's name field is ready for the next one
            wm.preset_name = "New Preset"
        return {'FINISHED'}


classes = (VISCOSCOPE_MT_fluid_presets, VISCOSCOPE_PT_fluid_presets, VISCOSCOPE_OT_fluid_preset_load,
           VISCOSCOPE_OT_fluid_preset_add)

"""Viscoscope fluid material presets, in Blender's own style (AddPresetBase, a preset menu in the
panel header). Presets are stored in the user's config (scripts/presets/viscoscope/fluid), never
inside the add-on folder.

A Blender preset is a Python file that Blender executes. AddPresetBase writes every value with
repr() and derives the file name from the preset name with as_filename() (only [A-Za-z0-9_-]
survive, see preset_filename), so no preset name or value can inject code; tests/blender/test_presets.py checks it.
"""

import os
import re

import bpy
from bl_operators.presets import AddPresetBase
from bl_ui.utils import PresetPanel

PRESET_SUBDIR = os.path.join("viscoscope", "fluid")

FLUID_FIELDS = ("description", "viscosity", "density", "surface_tension", "slip_length", "model",
                "consistency", "flow_index", "eta_infinity", "relaxation_time", "yield_stress", "color", "roughness",
                "transmission")


def user_preset_dir(create=True):
    return bpy.utils.user_resource('SCRIPTS', path=os.path.join("presets", PRESET_SUBDIR), create=create)


class VISCOSCOPE_MT_fluid_presets(bpy.types.Menu):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"
    draw = bpy.types.Menu.draw_preset


class VISCOSCOPE_PT_fluid_presets(PresetPanel, bpy.types.Panel):
    bl_label = "Viscoscope Fluid Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"
    preset_add_operator = "viscoscope.fluid_preset_add"


class VISCOSCOPE_OT_fluid_preset_add(AddPresetBase, bpy.types.Operator):
    """Save the fluid material (η, ρ, σ, model parameters, render colour) as a preset in your user config"""
    bl_idname = "viscoscope.fluid_preset_add"
    bl_label = "Save Fluid Preset"
    preset_menu = "VISCOSCOPE_MT_fluid_presets"
    preset_defines = ["fluid = bpy.context.scene.viscoscope.fluid"]
    preset_values = ["fluid." + name for name in FLUID_FIELDS]
    preset_subdir = PRESET_SUBDIR

    @staticmethod
    def as_filename(name):
        """Strict file name: Blender's own keeps control characters such as newlines."""
        return preset_filename(name)


def preset_filename(name):
    """[A-Za-z0-9_-] only, at most 64 characters, never empty."""
    cleaned = re.sub(r"[^A-Za-z0-9_-]+", "_", name.strip()).strip("_")
    return cleaned[:64].strip("_") or "Preset"


classes = (VISCOSCOPE_MT_fluid_presets, VISCOSCOPE_PT_fluid_presets, VISCOSCOPE_OT_fluid_preset_add)

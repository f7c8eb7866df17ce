"""The add-on registers, unregisters and re-registers cleanly."""

import addon_utils
import bpy

import conftest


def _viscoscope_types():
    return sorted(n for n in dir(bpy.types) if n.startswith(("VIEW3D_PT_viscoscope", "VISCOSCOPE_")))


def test_enable_registers_everything(addon):
    names = _viscoscope_types()
    for expected in ("VIEW3D_PT_viscoscope_reference", "VIEW3D_PT_viscoscope_identify",
                     "VIEW3D_PT_viscoscope_fluid", "VIEW3D_PT_viscoscope_transfer",
                     "VISCOSCOPE_OT_simulate", "VISCOSCOPE_OT_identify", "VISCOSCOPE_OT_add_cup",
                     "VISCOSCOPE_OT_fluid_preset_add", "VISCOSCOPE_MT_fluid_presets"):
        assert expected in names
    assert hasattr(bpy.types.Scene, "viscoscope")
    assert hasattr(bpy.types.Object, "viscoscope")
    assert conftest.MODULE in bpy.context.preferences.addons
    prefs = bpy.context.preferences.addons[conftest.MODULE].preferences
    assert prefs.threads == 0 and prefs.engine_path == ""


def test_panels_are_in_the_viscoscope_tab(addon):
    panels = [getattr(bpy.types, n) for n in dir(bpy.types) if n.startswith("VIEW3D_PT_viscoscope")]
    assert len(panels) >= 8
    for panel in panels:
        assert panel.bl_category == "Viscoscope"
        assert panel.bl_space_type == 'VIEW_3D' and panel.bl_region_type == 'UI'


def test_unregister_and_reregister(addon):
    conftest.disable_addon()
    try:
        assert _viscoscope_types() == []
        assert not hasattr(bpy.types.Scene, "viscoscope")
        assert conftest.MODULE not in bpy.context.preferences.addons
        from viscoscope import mantaflow
        assert mantaflow._recompute_on_resize not in bpy.app.handlers.depsgraph_update_post
    finally:
        conftest.enable_addon()
    assert "VISCOSCOPE_OT_simulate" in _viscoscope_types()
    assert addon_utils.check(conftest.MODULE) == (True, True)


def test_relative_imports_only():
    """No module imports the package by name (it is "viscoscope" or "bl_ext.*.viscoscope")."""
    import ast
    import os
    for root, _dirs, files in os.walk(conftest.ADDON_SRC):
        for name in files:
            if not name.endswith(".py"):
                continue
            path = os.path.join(root, name)
            tree = ast.parse(open(path, encoding="utf-8").read(), path)
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.level == 0:
                    assert node.module.split(".")[0] not in ("viscoscope", "addon"), path
                if isinstance(node, ast.Import):
                    for alias in node.names:
                        assert alias.name.split(".")[0] not in ("viscoscope", "addon"), path


def test_no_bare_except_and_engine_never_imports_bpy():
    import ast
    import os
    for root, _dirs, files in os.walk(conftest.ADDON_SRC):
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(root, name)
                tree = ast.parse(open(path, encoding="utf-8").read(), path)
                for node in ast.walk(tree):
                    assert not (isinstance(node, ast.ExceptHandler) and node.type is None), path
    for pure in ("engine.py", "units.py", "camera_math.py"):
        tree = ast.parse(open(os.path.join(conftest.ADDON_SRC, pure), encoding="utf-8").read())
        imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert not imported & {"bpy", "mathutils", "bmesh"}, pure

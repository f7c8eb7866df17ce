"""One contract between the add-on and the engine: the panel's names, units, bounds and defaults are
the engine's declarations (`viscoscope schema`), and every file the add-on writes through the engine,
the engine reads back (`viscoscope check`). Every power-law fluid the add-on exported was once
refused, because the two sides spelt the flow index differently and nothing read one with the other."""

import json
import os
import subprocess

import bpy
import pytest

from viscoscope import scene_export, schema
from viscoscope.operators import container, identify

# Declared parameters the panel leaves at the engine's defaults: the shear-dependent laws' viscosity caps.
NOT_IN_PANEL = {"eta_min", "eta_max"}


def _check(engine_path, *paths):
    proc = subprocess.run([engine_path, "check", *paths], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


@pytest.mark.engine
def test_shipped_schema_is_the_engines(engine_path):
    proc = subprocess.run([engine_path, "schema"], capture_output=True, text=True, timeout=60, check=True)
    assert json.loads(proc.stdout) == schema.SCHEMA, \
        "addon/engine_schema.json is stale: regenerate it with `viscoscope schema > addon/engine_schema.json`"


def test_the_docs_list_the_engines_effects():
    """docs/engine.md's table of diagnose's effects is the engine's (schema.EFFECTS, from its table of
    records), row for row, and the README names each."""
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(repo, "docs", "engine.md"), encoding="utf-8") as fh:
        rows = [line for line in fh if line.startswith("| `")]
    listed = [[cell.strip() for cell in row.strip().strip("|").split("|")] for row in rows]
    effects = [["`%s`" % e["name"], e["description"], e["source"]] for e in schema.EFFECTS]
    assert [row for row in listed if row[0] in {e[0] for e in effects}] == effects
    with open(os.path.join(repo, "README.md"), encoding="utf-8") as fh:
        readme = " ".join(fh.read().lower().split())  # as a reader sees it, whatever the line breaks and capitals
    for e in schema.EFFECTS:
        assert e["name"].replace("_", " ") in readme, e["name"]


def test_fluid_panel_holds_every_material_parameter_within_its_declared_bounds(ctx):
    fluid_rna = ctx.scene.viscoscope.fluid.bl_rna.properties
    material = {name for name, p in schema.PARAMETERS.items() if p["home"] in ("material", "material.model")}
    assert material - NOT_IN_PANEL <= set(fluid_rna.keys()), "the panel lacks " + str(material - NOT_IN_PANEL - set(fluid_rna.keys()))
    for name in material - NOT_IN_PANEL:
        prop, declared = fluid_rna[name], schema.PARAMETERS[name]
        # Blender keeps float properties in single precision.
        assert prop.hard_min == pytest.approx(declared["lower"], rel=1e-6), name
        assert prop.hard_max == pytest.approx(declared["upper"], rel=1e-6), name
        if declared["default"] is not None:
            assert prop.default == pytest.approx(declared["default"], rel=1e-6), name
        assert declared["unit"] in prop.name or declared["unit"] == "1", (name, prop.name)


def _cup_scene(ctx):
    container.add_cup(ctx, (0.0, 0.0, 0.0))
    ctx.scene.viscoscope.fill_volume = 1.0e-4


@pytest.mark.engine
@pytest.mark.parametrize("model", ['NEWTONIAN', 'POWER_LAW', 'CARREAU', 'HERSCHEL_BULKLEY'])
def test_engine_reads_back_every_material_model_the_addon_exports(ctx, tmp_work, engine_path, model):
    _cup_scene(ctx)
    fluid = ctx.scene.viscoscope.fluid
    fluid.model = model
    fluid.consistency, fluid.flow_index, fluid.yield_stress = 12.0, 0.6, 20.0
    fluid.eta_infinity, fluid.relaxation_time = 0.5, 0.2
    path = os.path.join(str(tmp_work), "scene.json")
    scene_export.export_scene(ctx.scene, path)
    assert "ok (viscoscope.scene)" in _check(engine_path, path)
    with open(path) as fh:
        written = json.load(fh)["material"]["model"]
    held = {name for name, p in schema.PARAMETERS.items()
            if p["home"] == "material.model" and written["type"] in p["types"]}
    assert set(written) - {"type"} == held - NOT_IN_PANEL


@pytest.mark.engine
def test_engine_reads_back_the_camera_and_the_job_the_addon_writes(ctx, tmp_work, engine_path):
    _cup_scene(ctx)
    bpy.ops.object.camera_add(location=(0.0, -0.5, 0.1), rotation=(1.45, 0.0, 0.0))
    vs = ctx.scene.viscoscope
    vs.camera = ctx.scene.camera = ctx.active_object
    # The job names the clip; reading the job only needs it to exist (identify extracts it).
    vs.video_path = os.path.join(str(tmp_work), "clip.mp4")
    open(vs.video_path, "wb").close()
    vs.background = 'LEADING_FRAMES'
    # Every extraction setting at the end of its panel range: the engine must take it.
    for name in ("mask_threshold", "close_diameter", "min_blob", "edge_coverage", "shadow_threshold"):
        setattr(vs, name, vs.bl_rna.properties[name].hard_max)
    folder = identify.identify_dir(ctx.scene)
    job, _note = identify.write_job(ctx, folder)
    out = _check(engine_path, os.path.join(folder, "blender_camera.json"), os.path.join(folder, "scene.json"), job)
    assert out.count(": ok (") == 3, out
    # The search's start and spread at the ends of their panel ranges: the engine must take each job.
    props = vs.bl_rna.properties
    for initial in (props["eta_initial"].hard_min, props["eta_initial"].hard_max):
        for spread in (props["eta_spread"].hard_min, props["eta_spread"].hard_max):
            vs.eta_initial, vs.eta_spread = initial, spread
            job, _note = identify.write_job(ctx, folder)
            assert ": ok (" in _check(engine_path, job), (initial, spread)


@pytest.mark.engine
def test_engine_refuses_a_misspelt_key_the_addon_might_write(ctx, tmp_work, engine_path):
    """The check above can fail: the engine does not skip keys it does not know."""
    _cup_scene(ctx)
    path = os.path.join(str(tmp_work), "scene.json")
    scene_export.export_scene(ctx.scene, path)
    with open(path) as fh:
        doc = json.load(fh)
    doc["material"]["surface_tenson"] = doc["material"].pop("surface_tension")
    with open(path, "w") as fh:
        json.dump(doc, fh)
    proc = subprocess.run([engine_path, "check", path], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "material.surface_tenson: unknown field; did you mean `surface_tension`?" in proc.stderr

"""Packaging: one version for bl_info and the manifest; the zip installs into a clean user config
and enables, finding its bundled engine."""

import os
import subprocess
import sys
import textwrap
import zipfile

import bpy
import pytest

import conftest

sys.path.insert(0, os.path.join(conftest.REPO, "scripts"))
import build_addon_zip  # noqa: E402


def test_bl_info_and_manifest_share_one_version():
    import tomllib
    with open(os.path.join(conftest.REPO, "blender_manifest.toml"), "rb") as fh:
        manifest = tomllib.load(fh)
    assert manifest["version"] == build_addon_zip.bl_info_version()
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["id"] == "viscoscope" and manifest["type"] == "add-on"
    for key in ("name", "tagline", "maintainer", "blender_version_min", "license", "platforms"):
        assert manifest[key], key
    assert "files" in manifest["permissions"]
    assert len(manifest["tagline"]) <= 64 and not manifest["tagline"].endswith(".")


def test_bl_info_targets_blender_3_4(addon):
    assert addon.bl_info["blender"] == (3, 4, 0)
    assert addon.bl_info["category"] == "Physics"


@pytest.fixture(scope="module")
def bundled_engine(tmp_path_factory):
    """The real engine when VISCOSCOPE_ENGINE is set, else the stand-in."""
    if os.environ.get("VISCOSCOPE_ENGINE"):
        return os.environ["VISCOSCOPE_ENGINE"]
    path = tmp_path_factory.mktemp("engine") / "viscoscope"
    path.write_text(conftest.FAKE_ENGINE)
    path.chmod(0o755)
    return str(path)


INSTALL_SCRIPT = textwrap.dedent('''
    import os, sys
    import bpy, addon_utils
    zip_path = sys.argv[sys.argv.index("--") + 1]
    assert bpy.ops.preferences.addon_install(filepath=zip_path) == {'FINISHED'}
    assert bpy.ops.preferences.addon_enable(module="viscoscope") == {'FINISHED'}
    assert "viscoscope" in bpy.context.preferences.addons
    assert hasattr(bpy.types, "VIEW3D_PT_viscoscope_identify")
    import viscoscope
    from viscoscope import prefs
    addon_dir = os.path.dirname(viscoscope.__file__)
    assert addon_dir.startswith(os.environ["BLENDER_USER_SCRIPTS"]), addon_dir
    engine = prefs.find_engine(bpy.context)
    assert engine == os.path.join(addon_dir, "bin", "viscoscope"), engine
    assert os.access(engine, os.X_OK)
    from viscoscope import engine as engine_mod
    assert engine_mod.engine_version(engine) == prefs.addon_version(), engine_mod.engine_version(engine)
    bpy.ops.preferences.addon_disable(module="viscoscope")
    assert not hasattr(bpy.types, "VIEW3D_PT_viscoscope_identify")
    print("INSTALL-OK", viscoscope.bl_info["version"])
''')


def test_zip_installs_into_a_clean_user_config(tmp_path, bundled_engine):
    zip_path = build_addon_zip.build(str(tmp_path / "dist"), bundled_engine)
    with zipfile.ZipFile(zip_path) as zf:
        names = zf.namelist()
        assert "viscoscope/__init__.py" in names and "viscoscope/blender_manifest.toml" in names
        assert "viscoscope/bin/viscoscope" in names
        for script in build_addon_zip.ENGINE_SCRIPTS:
            assert "viscoscope/scripts/" + script in names
        assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
        assert all(n.startswith("viscoscope/") for n in names)
    script = tmp_path / "install.py"
    script.write_text(INSTALL_SCRIPT)
    env = dict(os.environ)
    env.pop("VISCOSCOPE_ENGINE", None)
    env["BLENDER_USER_CONFIG"] = str(tmp_path / "config")
    env["BLENDER_USER_SCRIPTS"] = str(tmp_path / "scripts")
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
                           "--python", str(script), "--", zip_path],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "INSTALL-OK (0, 1, 0)" in proc.stdout


def test_build_refuses_mismatched_versions(tmp_path, monkeypatch):
    bad = tmp_path / "blender_manifest.toml"
    bad.write_text('schema_version = "1.0.0"\nversion = "9.9.9"\n')
    monkeypatch.setattr(build_addon_zip, "MANIFEST", str(bad))
    monkeypatch.setattr(build_addon_zip, "manifest_version", lambda path=str(bad): "9.9.9")
    with pytest.raises(SystemExit, match="!= blender_manifest.toml version 9.9.9"):
        build_addon_zip.build(str(tmp_path / "out"), None)


def _engine_script_lookup(engine, name):
    """Where the engine looks for a helper script (native/src/cli/scripts.cpp, findScript): scripts/NAME
    in the executable's folder or up to five folders above it ($VISCOSCOPE_SCRIPTS unset)."""
    here = os.path.dirname(os.path.realpath(engine))
    for _ in range(6):
        candidate = os.path.join(here, "scripts", name)
        if os.path.exists(candidate):
            return candidate
        if os.path.dirname(here) == here:
            break
        here = os.path.dirname(here)
    return None


def test_packaged_engine_finds_its_scripts(tmp_path, bundled_engine):
    """Installed from the zip, the engine finds plot_identification.py and render_reference.py beside
    it, not "skipped: scripts/plot_identification.py not found"."""
    zip_path = build_addon_zip.build(str(tmp_path / "dist"), bundled_engine)
    installed = tmp_path / "addons"
    with zipfile.ZipFile(zip_path) as zf:
        zf.extractall(installed)
    engine = installed / "viscoscope" / "bin" / "viscoscope"
    for name in build_addon_zip.ENGINE_SCRIPTS:
        found = _engine_script_lookup(str(engine), name)
        assert found == str(installed / "viscoscope" / "scripts" / name), found
        with open(found, "rb") as packaged, open(os.path.join(conftest.REPO, "scripts", name), "rb") as source:
            assert packaged.read() == source.read()


@pytest.mark.engine
def test_packaged_engine_draws_the_plots(ctx, tmp_work, tmp_path, engine_path):
    """The engine unpacked from the zip, on a small identification, draws its plots: its "done" event
    does not say "skipped: scripts/plot_identification.py not found"."""
    import json
    import test_identify_real
    from viscoscope import engine
    from viscoscope.operators import identify
    zip_path = build_addon_zip.build(str(tmp_path / "dist"), engine_path)
    with zipfile.ZipFile(zip_path) as zf:
        zf.extractall(tmp_path / "addons")
    packaged = tmp_path / "addons" / "viscoscope" / "bin" / "viscoscope"
    packaged.chmod(0o755)  # as find_engine does for a zip install
    test_identify_real._capture_scene(ctx)
    vs = ctx.scene.viscoscope
    vs.video_path, _areas = test_identify_real._make_reference(ctx, engine_path, str(tmp_work))
    vs.identify_resolution, vs.max_generations, vs.grid_placements = 12, 1, 1
    job, _note = identify.write_job(ctx, identify.identify_dir(ctx.scene))
    env = {k: v for k, v in os.environ.items() if k != "VISCOSCOPE_SCRIPTS"}
    proc = subprocess.run(engine.identify_args(str(packaged), job, str(tmp_path / "out")), env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    done = [e for e in map(json.loads, proc.stdout.splitlines()) if e.get("event") == "done"][-1]
    assert "not found" not in done["plots"], done["plots"]
    matplotlib = subprocess.run(["/usr/bin/python3", "-c", "import matplotlib"]).returncode == 0
    assert (done["plots"] == "ok") == matplotlib, done["plots"]

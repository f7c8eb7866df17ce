"""The engine runner: non-blocking progress, cancel (SIGTERM → exit 3), crash and bad-input errors,
and the Simulate operator on top of it. A stand-in engine (conftest.FAKE_ENGINE) tests the contract
everywhere; the real engine is tested when VISCOSCOPE_ENGINE is set."""

import json
import os
import time

import bpy
import pytest

from viscoscope import engine
from viscoscope.operators import container, runner


def _wait_for(predicate, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return False


def test_find_engine_order(tmp_path, fake_engine):
    env = {}
    addon_dir = str(tmp_path / "addon")
    os.makedirs(os.path.join(addon_dir, "bin"))
    with pytest.raises(engine.EngineError, match="not found"):
        engine.find_engine("", addon_dir, env)
    bundled = os.path.join(addon_dir, "bin", "viscoscope")
    os.symlink(fake_engine, bundled)
    assert engine.find_engine("", addon_dir, env) == bundled
    env[engine.ENGINE_ENV] = fake_engine
    assert engine.find_engine("", addon_dir, env) == fake_engine
    with pytest.raises(engine.EngineError, match="from preferences is not an executable file"):
        engine.find_engine(str(tmp_path / "nope"), addon_dir, env)
    env[engine.ENGINE_ENV] = str(tmp_path / "missing")
    with pytest.raises(engine.EngineError, match="VISCOSCOPE_ENGINE is not an executable"):
        engine.find_engine("", addon_dir, env)


def test_progress_is_read_without_blocking(tmp_path, fake_engine, monkeypatch):
    monkeypatch.setenv("FAKE_ENGINE_FRAMES", "6")
    job = engine.EngineJob(engine.simulate_args(fake_engine, "scene.json", str(tmp_path / "out"))).start()
    t0 = time.monotonic()
    first = job.poll()
    assert time.monotonic() - t0 < 0.05  # poll never waits
    events = list(first)
    assert _wait_for(lambda: job.finished)
    events += job.poll()
    progress = [e for e in events if e["event"] == "progress"]
    assert [e["frame"] for e in progress] == [1, 2, 3, 4, 5, 6]
    assert events[-1]["event"] == "done"
    assert job.returncode == 0 and job.message() == "Finished"
    assert "not json noise" in job.noise
    assert engine.progress_fraction(progress[-1]) == 1.0


def test_cancel_sends_sigterm_and_engine_exits_3(tmp_path, fake_engine, monkeypatch):
    monkeypatch.setenv("FAKE_ENGINE_FRAMES", "1000")
    job = engine.EngineJob(engine.simulate_args(fake_engine, "scene.json", str(tmp_path / "out"))).start()
    assert _wait_for(lambda: any(e["event"] == "progress" for e in job.poll()))
    job.cancel()
    assert _wait_for(lambda: job.finished)
    assert job.returncode == engine.EXIT_CANCELLED
    assert "Cancelled" in job.message()
    assert os.path.isfile(tmp_path / "out" / "state.json")


@pytest.mark.parametrize("mode, rc, text", [
    ("bad", 2, "Bad input: scene.json: material.viscosity must be >= 0"),
    ("crash", -11, "Engine crashed (SIGSEGV): segmentation fault in StokesSolver"),
])
def test_errors_are_one_line(tmp_path, fake_engine, monkeypatch, mode, rc, text):
    monkeypatch.setenv("FAKE_ENGINE_MODE", mode)
    job = engine.EngineJob(engine.simulate_args(fake_engine, "s.json", str(tmp_path / "o"))).start()
    job.wait(30)
    assert job.returncode == rc
    assert job.message() == text


def test_missing_executable_is_a_clear_error(tmp_path):
    with pytest.raises(engine.EngineError, match="Cannot start the engine"):
        engine.EngineJob([str(tmp_path / "nope"), "simulate"]).start()


def _transfer_scene(ctx):
    container.add_domain(ctx, (-0.1, -0.1, 0), (0.1, 0.1, 0.2))
    bpy.ops.mesh.primitive_cube_add(size=0.04, location=(0, 0, 0.1))
    ctx.active_object.name = "Viscoscope blob"
    ctx.active_object.viscoscope.role = 'LIQUID'
    ctx.scene.viscoscope.sim_resolution = 16
    ctx.scene.viscoscope.sim_frames = 4


def test_simulate_operator_crash_leaves_scene_untouched(ctx, tmp_work, fake_engine, use_engine, monkeypatch):
    use_engine(fake_engine)
    _transfer_scene(ctx)
    monkeypatch.setenv("FAKE_ENGINE_MODE", "crash")
    names = sorted(o.name for o in bpy.data.objects)
    volumes = len(bpy.data.volumes)
    with pytest.raises(RuntimeError, match="Engine crashed"):  # bpy.ops raises on an ERROR report
        bpy.ops.viscoscope.simulate('EXEC_DEFAULT')
    st = ctx.scene.viscoscope.simulate_job
    assert st.error == "Engine crashed (SIGSEGV): segmentation fault in StokesSolver"
    assert not runner.is_running("simulate")
    assert sorted(o.name for o in bpy.data.objects) == names and len(bpy.data.volumes) == volumes
    # the exported scene is valid JSON next to the run
    with open(os.path.join(str(tmp_work), "transfer", "scene.json")) as fh:
        assert json.load(fh)["domain"]["resolution"] == 16


def test_simulate_operator_reports_missing_engine_and_bad_scene(ctx, tmp_work, tmp_path, use_engine):
    use_engine(str(tmp_path / "no-such-engine"))
    _transfer_scene(ctx)
    with pytest.raises(RuntimeError, match="is not an executable file"):
        bpy.ops.viscoscope.simulate('EXEC_DEFAULT')
    assert "is not an executable file" in ctx.scene.viscoscope.simulate_job.error


def test_simulate_operator_bad_scene(ctx, tmp_work, fake_engine, use_engine):
    use_engine(fake_engine)
    with pytest.raises(RuntimeError, match="role 'Domain'"):
        bpy.ops.viscoscope.simulate('EXEC_DEFAULT')
    assert "role 'Domain'" in ctx.scene.viscoscope.simulate_job.error


def test_pump_cancel_via_runner(ctx, tmp_work, fake_engine, use_engine, monkeypatch):
    """What the modal timer does: start, pump while running, Cancel button, pump until stopped."""
    use_engine(fake_engine)
    _transfer_scene(ctx)
    monkeypatch.setenv("FAKE_ENGINE_FRAMES", "1000")
    op = bpy.types.VISCOSCOPE_OT_simulate
    from viscoscope.operators.simulate import VISCOSCOPE_OT_simulate
    args, out_dir = VISCOSCOPE_OT_simulate.prepare(None, ctx)
    runner.start(ctx, "simulate", args, out_dir, lambda c, d: None)
    assert _wait_for(lambda: runner.pump(ctx, "simulate") == 'RUNNING' and ctx.scene.viscoscope.simulate_job.progress > 0)
    assert ctx.scene.viscoscope.simulate_job.status.startswith("Frame ")
    assert not op.poll(ctx)  # a second run is refused while one is running
    assert bpy.ops.viscoscope.cancel_job(kind='simulate') == {'FINISHED'}
    assert _wait_for(lambda: runner.pump(ctx, "simulate") != 'RUNNING')
    st = ctx.scene.viscoscope.simulate_job
    assert st.status.startswith("Cancelled") and st.can_resume and not runner.is_running("simulate")


def test_engine_warning_stays_in_the_panel_until_the_next_run(ctx, tmp_work, fake_engine, use_engine, monkeypatch):
    use_engine(fake_engine)
    _transfer_scene(ctx)
    from viscoscope.operators.simulate import VISCOSCOPE_OT_simulate
    message = "solids[1] (cup): its hole is 1.6 cells across at resolution 16"
    monkeypatch.setenv("FAKE_ENGINE_WARNING", message)
    args, out_dir = VISCOSCOPE_OT_simulate.prepare(None, ctx)
    runner.start(ctx, "simulate", args, out_dir, lambda c, d: None)
    assert _wait_for(lambda: runner.pump(ctx, "simulate") != 'RUNNING')
    st = ctx.scene.viscoscope.simulate_job
    assert st.warning == message and not st.error
    monkeypatch.delenv("FAKE_ENGINE_WARNING")
    runner.start(ctx, "simulate", args, out_dir, lambda c, d: None)
    assert st.warning == ""
    assert _wait_for(lambda: runner.pump(ctx, "simulate") != 'RUNNING')
    assert st.warning == ""


# ---- the real engine -----------------------------------------------------------------------------

@pytest.mark.engine
def test_real_engine_simulate_progress_and_cancel(ctx, tmp_work, engine_path):
    from viscoscope import scene_export
    _transfer_scene(ctx)
    ctx.scene.viscoscope.sim_frames = 200
    scene_path = os.path.join(str(tmp_work), "scene.json")
    scene_export.export_scene(ctx.scene, scene_path)
    job = engine.EngineJob(engine.simulate_args(engine_path, scene_path, str(tmp_work / "out"))).start()
    assert _wait_for(lambda: job.poll() and job.last_progress is not None or job.finished, 120)
    assert not job.finished, job.message()
    progress = job.last_progress
    for key in ("frame", "frames", "time", "elapsed", "remaining_s"):
        assert key in progress
    assert "step" in progress or "steps" in progress  # the contract says "step"; the engine writes "steps"
    job.cancel()
    job.wait(120)
    assert job.returncode == engine.EXIT_CANCELLED, job.message()


@pytest.mark.engine
def test_real_engine_rejects_bad_input(tmp_path, engine_path):
    bad = tmp_path / "scene.json"
    bad.write_text(json.dumps({"format": "viscoscope.scene", "version": 1, "material": {"viscosity": -1}}))
    job = engine.EngineJob(engine.simulate_args(engine_path, str(bad), str(tmp_path / "out"))).start()
    job.wait(60)
    assert job.returncode == engine.EXIT_BAD_INPUT
    assert job.message().startswith("Bad input: ") and "\n" not in job.message()


@pytest.mark.engine
def test_real_engine_simulate_operator_imports_vdb(ctx, tmp_work, engine_path, use_engine):
    use_engine(engine_path)
    _transfer_scene(ctx)
    assert bpy.ops.viscoscope.simulate('EXEC_DEFAULT') == {'FINISHED'}, ctx.scene.viscoscope.simulate_job.error
    obj = bpy.data.objects["Viscoscope Liquid"]
    mod = obj.modifiers[0]
    assert mod.type == 'VOLUME_TO_MESH' and mod.grid_name == "surface"
    volume = mod.object.data
    assert mod.object.type == 'VOLUME' and volume.is_sequence
    # frame_00000.vdb is the initial state at the start frame, then one file per simulated frame
    assert volume.frame_duration == 5 and volume.frame_start == ctx.scene.frame_start
    ctx.scene.frame_set(ctx.scene.frame_start + 3)
    volume.grids.load()
    assert volume.grids.frame_filepath.endswith("frame_00003.vdb"), volume.grids.frame_filepath
    assert {"surface", "velocity", "pressure"} <= {g.name for g in volume.grids}
    assert obj.active_material is not None
    evaluated = obj.evaluated_get(ctx.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    assert len(mesh.vertices) > 0
    evaluated.to_mesh_clear()


def test_threads_flag_only_when_the_engine_accepts_it(fake_engine):
    assert "--threads" not in engine.simulate_args(fake_engine, "s.json", "out", threads=4)
    assert "--threads" not in engine.simulate_args(fake_engine, "s.json", "out", threads=0)


@pytest.mark.engine
def test_engine_version_matches_addon(addon, engine_path):
    from viscoscope import prefs
    assert engine.engine_version(engine_path) == prefs.addon_version()


@pytest.mark.engine
def test_real_engine_cancel_through_the_operator_runner(ctx, tmp_work, engine_path, use_engine):
    from viscoscope.operators.simulate import VISCOSCOPE_OT_simulate
    use_engine(engine_path)
    _transfer_scene(ctx)
    ctx.scene.viscoscope.sim_frames = 500
    names = sorted(o.name for o in bpy.data.objects)
    args, out_dir = VISCOSCOPE_OT_simulate.prepare(None, ctx)
    runner.start(ctx, "simulate", args, out_dir, lambda c, d: pytest.fail("must not import after cancel"))
    assert _wait_for(lambda: runner.pump(ctx, "simulate") == 'RUNNING' and ctx.scene.viscoscope.simulate_job.progress > 0, 120)
    assert bpy.ops.viscoscope.cancel_job(kind='simulate') == {'FINISHED'}
    assert _wait_for(lambda: runner.pump(ctx, "simulate") != 'RUNNING', 120)
    st = ctx.scene.viscoscope.simulate_job
    assert st.status.startswith("Cancelled") and st.error == ""
    assert sorted(o.name for o in bpy.data.objects) == names


def test_progress_line_names_the_coarse_phase():
    event = {"event": "progress", "stage": "identify", "generation": 3, "generations": 40, "fidelity": "coarse",
             "best_eta": 9.4627, "best_E": 0.0261, "remaining_s": 364.2}
    line = runner.describe_progress(event)
    assert line.startswith("Generation 3/40 (coarse) · best η 9.463 Pa·s · best E 0.0261 · ")
    event["fidelity"] = "full"
    assert runner.describe_progress(event).startswith("Generation 3/40 · best η")

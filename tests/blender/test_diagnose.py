"""Diagnose end to end through the real engine, on a measured track: the panel's reference as a
lab's radius record (CSV), the thin-film forward model, the Diagnose operator with its progress,
Cancel and Resume, the conclusion and figures in the panel, and Apply Effect writing the chosen law
into the Fluid Material, which the engine then reads back.

The tracks are not made by the engine: they are the similarity laws of a gravity current fed at a
constant flux, rounded to half a millimetre as a lab's pixels would be. A Newtonian current spreads
as Huppert's r = 0.715 (g Q³/3ν)^{1/8} t^{1/2}; a power-law one as t^{(2n+2)/(3n+5)}, which no
Newtonian liquid does."""

import json
import math
import os
import subprocess

import bpy
import pytest

from viscoscope import engine, schema, scene_export
from viscoscope.operators.diagnose import diagnose_dir, suggestions

pytestmark = pytest.mark.engine

DENSITY = 1000.0  # kg/m³
FLUX = 2e-6       # m³/s through the hole
ETA = 20.0        # Pa·s: the Newtonian track's viscosity
HOLE = 0.005      # m, the emitter's radius
INTERVAL = 4.0    # s between the track's samples
SAMPLES = 30


def _huppert_radius(t, flux=FLUX):
    return 0.715 * (9.81 * flux ** 3 / (3 * ETA / DENSITY)) ** 0.125 * t ** 0.5


def _write_track(path, radius_at):
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("time_s,radius_m\n")
        for i in range(1, SAMPLES + 1):
            t = INTERVAL * i
            fh.write("%g,%.4f\n" % (t, round(radius_at(t) / 0.0005) * 0.0005))
    return path


def _add_object(scene, name, role, location=(0.0, 0.0, 0.0), corners=None):
    data = None
    if corners is not None:
        data = bpy.data.meshes.new(name)
        data.from_pydata([(x, y, z) for x in corners[0] for y in corners[1] for z in corners[2]], [], [])
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    scene.collection.objects.link(obj)
    obj.viscoscope.role = role
    return obj


def _film_scene(scene, track_csv, cells=150, generations=12, flux=FLUX):
    """A ground plane, a hole pumping `flux` up through it at the origin, the panel set to fit the
    measured radius with the thin film on `cells` cells across the domain."""
    _add_object(scene, "Domain", 'DOMAIN', corners=((-0.15, 0.15), (-0.15, 0.15), (-0.01, 0.05)))
    _add_object(scene, "Ground", 'GROUND')
    emitter = _add_object(scene, "Hole", 'EMITTER').viscoscope
    emitter.emitter_radius, emitter.emitter_flux = HOLE, flux
    emitter.emitter_start, emitter.emitter_end = 0.0, 1e4
    scene.render.fps, scene.render.fps_base = 1, INTERVAL  # a simulation frame per sample
    scene.use_gravity, scene.gravity = True, (0.0, 0.0, -9.81)
    vs = scene.viscoscope
    vs.sim_frames = SAMPLES + 1
    vs.sim_resolution = cells
    vs.fluid.density = DENSITY
    vs.reference_kind = 'TRACK'
    vs.track_csv = track_csv
    vs.track_observable = 'radius'
    vs.track_origin = (0.0, 0.0, 0.0)
    vs.forward_model = 'thin_film'
    vs.identify_resolution = cells
    vs.eta_initial, vs.eta_spread = 10.0, 3.0
    vs.max_generations = generations


@pytest.fixture(autouse=True)
def forget_plots(tmp_work):
    """Later tests look plots up by name ("convergence.png", "diagnosis.png")."""
    yield
    for img in [i for i in bpy.data.images if bpy.path.abspath(i.filepath).startswith(str(tmp_work))]:
        bpy.data.images.remove(img)


def test_diagnose_a_newtonian_track_cancel_resume_and_no_missing_effect(ctx, tmp_work, engine_path, use_engine,
                                                                        press_cancel):
    use_engine(engine_path)
    _film_scene(ctx.scene, _write_track(os.path.join(str(tmp_work), "huppert.csv"), _huppert_radius))
    vs = ctx.scene.viscoscope
    out_dir = os.path.join(diagnose_dir(ctx.scene), "out")

    # Press Cancel at the first generation the engine reports, as the panel's button would.
    st = vs.diagnose_job
    seen, jobs = press_cancel("diagnose", lambda status: "Generation" in status.status)
    assert bpy.ops.viscoscope.diagnose('EXEC_DEFAULT') == {'CANCELLED'}
    job = json.load(open(os.path.join(diagnose_dir(ctx.scene), "job.json")))
    assert job["forward_model"] == "thin_film" and "video" not in job and "camera" not in job
    assert job["track"]["observable"] == "radius" and job["track"]["column"] == "radius_m"
    assert "grid_placements" not in job
    assert jobs[0].returncode == engine.EXIT_CANCELLED, jobs[0].stderr
    assert st.can_resume and st.status == "Cancelled; Resume continues"
    assert os.path.isfile(os.path.join(out_dir, "fits", "base", "checkpoint.json"))
    assert not os.path.exists(os.path.join(out_dir, "diagnosis.json")) and not vs.diagnosis_conclusion

    assert bpy.ops.viscoscope.diagnose_resume('EXEC_DEFAULT') == {'FINISHED'}, st.error
    statuses = [s for n, p, s in seen if n == 2]
    # The resumed run went on to the candidates. A poll shows only the last of the lines since the
    # one before, so a candidate's "Fit k/" line may be passed over; its generations' lines name it.
    candidates = [s for s in statuses if (s.startswith("Fit ") and not s.startswith("Fit 1/"))
                  or (" · Generation " in s and not s.startswith("base"))]
    assert candidates, statuses
    progress = [p for n, p, s in seen if n == 2]
    assert progress == sorted(progress) and st.progress == pytest.approx(100.0), progress
    assert vs.diagnosis_verdict == "no_missing_effect", vs.diagnosis_conclusion + "\n" + vs.diagnosis_report
    assert vs.diagnosis_conclusion.startswith("no missing effect: none of shear thinning")
    report = vs.diagnosis_report.splitlines()
    assert "Noise floor: none (the forward model is deterministic)" in report, report
    assert any(line.startswith("Error before → after:") and "track" in line for line in report), report
    base = next(line for line in report if line.startswith("Base: "))
    eta = float(base.split("η ")[1].split()[0])
    # Huppert's law is the point-source limit; the film's disc feeds a 5 mm hole (film_test: within
    # 1 % of the law at 300 cells, here 150 and early times, where r ∝ η^(-1/8) is insensitive).
    assert 0.7 * ETA < eta < 1.5 * ETA, base
    assert any(line.startswith("side_walls not tried") for line in report), report
    assert not vs.diagnosis_material
    assert not bpy.ops.viscoscope.apply_effect.poll()
    # Every candidate scores its base-equivalent point too (a power law at n = 1 is the base), so none
    # fits the fitted frames worse than the base: from their own starts, 12 generations left the power
    # law's 3.8 times worse.
    diagnosis = json.load(open(os.path.join(out_dir, "diagnosis.json")))
    # The panel's budget is the whole diagnosis's, shared by its fits.
    assert diagnosis["time_budget_s"] == pytest.approx(60 * vs.diagnosis_budget_minutes)
    # The base's share of the planned fits: itself, with three shares, and four candidates with one
    # each (side walls are not tried).
    assert diagnosis["base"]["time_budget_s"] == pytest.approx(60 * vs.diagnosis_budget_minutes * 3 / (3 + 4))
    for candidate in diagnosis["candidates"]:
        limit = (1 + 1e-9 if candidate["model"] == "shear_thinning" else 1.02) * diagnosis["base"]["fitted_E"]
        assert candidate["fitted_E"] <= limit, candidate["model"]
    assert bpy.data.images.get("diagnosis.png") is not None
    print("\n[diagnose] Newtonian track: %s; %s" % (vs.diagnosis_conclusion, base))

    # A changed job runs afresh in the same folder: the earlier run's checkpoints would be refused.
    vs.eta_initial = 30.0
    assert bpy.ops.viscoscope.diagnose('EXEC_DEFAULT') == {'FINISHED'}, st.error
    assert vs.diagnosis_verdict == "no_missing_effect", vs.diagnosis_conclusion


def test_diagnose_finds_shear_thinning_and_apply_writes_the_power_law(ctx, tmp_work, engine_path, use_engine):
    use_engine(engine_path)
    n = 0.4
    exponent = (2 * n + 2) / (3 * n + 5)
    t_mid = INTERVAL * SAMPLES / 2

    def power_law_radius(t):  # through the Newtonian track's radius at mid-record
        return _huppert_radius(t_mid) * (t / t_mid) ** exponent
    # 1 mm cells and 30 generations: on 2 mm cells the film's steep power-law front fits n = 0.58,
    # and with 12 generations a Bingham liquid predicted the held-out third better than an
    # unconverged power law (tests/bench/FINDINGS.md, "Diagnose in the panel").
    _film_scene(ctx.scene, _write_track(os.path.join(str(tmp_work), "thinning.csv"), power_law_radius),
                cells=300, generations=30)
    vs = ctx.scene.viscoscope
    out_dir = os.path.join(diagnose_dir(ctx.scene), "out")
    assert bpy.ops.viscoscope.diagnose('EXEC_DEFAULT') == {'FINISHED'}, vs.diagnose_job.error
    assert vs.diagnosis_verdict == "missing_effect", vs.diagnosis_conclusion + "\n" + vs.diagnosis_report
    assert vs.diagnosis_conclusion.startswith("missing effect: shear thinning (shear_thinning)"), vs.diagnosis_conclusion
    assert vs.diagnosis_effect == "shear_thinning"
    errors = next(line for line in vs.diagnosis_report.splitlines() if line.startswith("Error before → after"))
    before, after = (float(x.rstrip(" %;")) for x in errors.split("track ")[1].split(" → "))
    assert after <= 0.5 * before, vs.diagnosis_report

    diagnosis = json.load(open(os.path.join(out_dir, "diagnosis.json")))
    chosen = next(c for c in diagnosis["candidates"] if c["model"] == "shear_thinning")
    assert bpy.ops.viscoscope.apply_effect('EXEC_DEFAULT') == {'FINISHED'}
    fluid = vs.fluid
    assert fluid.model == 'POWER_LAW'
    assert fluid.flow_index == pytest.approx(chosen["parameters"]["flow_index"]["value"], rel=1e-6)
    assert fluid.consistency == pytest.approx(chosen["parameters"]["consistency"]["value"], rel=1e-6)
    assert abs(fluid.flow_index - n) < 0.15, fluid.flow_index
    assert "thinning.csv" in fluid.identified_from and "Shear thinning" in fluid.identified_from
    assert vs.diagnosis_applied and not bpy.ops.viscoscope.apply_effect.poll()

    # The applied material is one the engine reads, with the law and values the diagnosis found.
    path = os.path.join(str(tmp_work), "applied_scene.json")
    scene_export.export_scene(ctx.scene, path)
    proc = subprocess.run([engine_path, "check", path], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    exported = json.load(open(path))["material"]["model"]
    assert exported["type"] == "power_law"
    assert exported["flow_index"] == pytest.approx(chosen["material"]["model"]["flow_index"], rel=1e-6)
    assert schema.PARAMETERS["flow_index"]["lower"] <= exported["flow_index"] <= 1.0
    print("\n[diagnose] power-law track (n = %.2f, exponent %.4f): %s; applied K %.4g, n %.4f; %s"
          % (n, exponent, vs.diagnosis_conclusion, fluid.consistency, fluid.flow_index,
             errors))


def test_identify_on_a_measured_track_and_again_after_a_change(ctx, tmp_work, engine_path, use_engine):
    """Identify a measured track alone; a second Identify of a changed job starts afresh instead of
    being refused the first run's checkpoint."""
    use_engine(engine_path)
    _film_scene(ctx.scene, _write_track(os.path.join(str(tmp_work), "huppert.csv"), _huppert_radius))
    vs = ctx.scene.viscoscope
    assert bpy.ops.viscoscope.identify('EXEC_DEFAULT') == {'FINISHED'}, vs.identify_job.error
    first = vs.result_eta
    assert 0.7 * ETA < first < 1.5 * ETA and vs.result_footage == "huppert.csv"
    vs.eta_initial = 40.0
    assert bpy.ops.viscoscope.identify('EXEC_DEFAULT') == {'FINISHED'}, vs.identify_job.error
    assert vs.result_eta == pytest.approx(first, rel=0.1)
    assert math.isfinite(vs.result_eta_low) and vs.result_eta_low < vs.result_eta < vs.result_eta_high


def test_a_missing_track_is_one_clear_line(ctx, tmp_work, engine_path, use_engine):
    use_engine(engine_path)
    _film_scene(ctx.scene, os.path.join(str(tmp_work), "nowhere.csv"))
    with pytest.raises(RuntimeError, match="measured track CSV not found: .*nowhere.csv"):
        bpy.ops.viscoscope.diagnose('EXEC_DEFAULT')
    assert "nowhere.csv" in ctx.scene.viscoscope.diagnose_job.error


def test_a_budget_that_cannot_hold_the_chosen_effect_offers_one_that_would(ctx, tmp_work, engine_path, use_engine):
    """One effect chosen and a budget far under a generation: the engine fits the base and no
    candidate, and the panel says it cannot tell, shows the grid it ran on, and offers a button that
    sets the budget the engine predicts would hold the chosen effect's fit."""
    use_engine(engine_path)
    _film_scene(ctx.scene, _write_track(os.path.join(str(tmp_work), "huppert.csv"), _huppert_radius))
    vs = ctx.scene.viscoscope
    vs.diagnosis_effects = set()
    with pytest.raises(RuntimeError, match="no effect to try"):
        bpy.ops.viscoscope.diagnose('EXEC_DEFAULT')
    vs.diagnosis_effects = {"shear_thinning"}
    vs.diagnosis_budget_minutes = 1e-4
    assert bpy.ops.viscoscope.diagnose('EXEC_DEFAULT') == {'FINISHED'}, vs.diagnose_job.error
    diagnosis = json.load(open(os.path.join(diagnose_dir(ctx.scene), "out", "diagnosis.json")))
    assert not diagnosis["candidates"]
    assert [n["effect"] for n in diagnosis["not_tried"]] == ["shear_thinning"], diagnosis["not_tried"]
    assert diagnosis["not_tried"][0]["why"].startswith("the time budget")
    assert vs.diagnosis_verdict == "cannot_tell", vs.diagnosis_conclusion
    assert vs.diagnosis_grid.startswith("Ran at resolution 150 on "), vs.diagnosis_grid
    minutes = math.ceil(diagnosis["suggested_settings"]["time_budget_s"] / 60.0)
    assert ("time_budget_s", minutes, "Set Time Budget to %d min" % minutes) in suggestions(vs)
    assert bpy.ops.viscoscope.use_suggestion(setting="time_budget_s") == {'FINISHED'}
    assert vs.diagnosis_budget_minutes == minutes
    assert all(setting != "time_budget_s" for setting, _v, _t in suggestions(vs))
    with pytest.raises(RuntimeError, match="suggests no resolution"):
        bpy.ops.viscoscope.use_suggestion(setting="resolution")


def test_two_runs_of_one_liquid_are_fitted_together(ctx, tmp_work, engine_path, use_engine, request):
    """A second scene pumping twice the flux is another run of the same liquid: the job holds both,
    each with its own scene and track and the first scene's material, and Identify fits them together."""
    use_engine(engine_path)
    work = str(tmp_work)
    _film_scene(ctx.scene, _write_track(os.path.join(work, "slow.csv"), _huppert_radius))
    other = bpy.data.scenes.new("Fast pour")
    request.addfinalizer(lambda: bpy.data.scenes.remove(other))
    _film_scene(other, _write_track(os.path.join(work, "fast.csv"), lambda t: _huppert_radius(t, 2 * FLUX)),
                flux=2 * FLUX)
    other.viscoscope.fluid.density = 1400.0  # not what the job uses: the runs share the first scene's liquid
    vs = ctx.scene.viscoscope
    assert bpy.ops.viscoscope.add_run() == {'FINISHED'}
    assert vs.runs[0].scene == other
    assert bpy.ops.viscoscope.identify('EXEC_DEFAULT') == {'FINISHED'}, vs.identify_job.error
    folder = os.path.join(scene_export.work_dir(ctx.scene), "identify")
    job = json.load(open(os.path.join(folder, "job.json")))
    assert [r["scene"] for r in job["runs"]] == ["scene.json", "run1_scene.json"]
    assert [os.path.basename(r["track"]["csv"]) for r in job["runs"]] == ["slow.csv", "fast.csv"]
    assert "scene" not in job and "track" not in job
    second = json.load(open(os.path.join(folder, "run1_scene.json")))
    assert second["material"]["density"] == DENSITY and second["liquids"][0]["flux"] == pytest.approx(2 * FLUX)
    result = json.load(open(os.path.join(folder, "out", "result.json")))
    assert len(result["run_E"]) == 2
    assert 0.7 * ETA < vs.result_eta < 1.5 * ETA
    assert vs.result_footage == "slow.csv and fast.csv"

    # A run without a scene is one clear line, before the engine starts.
    vs.runs.add()
    with pytest.raises(RuntimeError, match="run 3 has no scene"):
        bpy.ops.viscoscope.identify('EXEC_DEFAULT')

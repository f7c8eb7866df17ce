"""Calibrate Mantaflow to Footage end to end: the real operator, the real engine's `score`, real
Mantaflow bakes in a background Blender.

The reference avoids the inverse crime: Mantaflow bakes the same liquid column at a known
viscosity_value on a finer grid than the calibration bakes it, and the engine's exact silhouettes of
that bake (`score` against an empty reference, whose difference image is then the silhouette) are
written as extracted reference masks where Identify leaves its own."""

import json
import math
import os
import subprocess
import sys
import time

import bpy
import pytest
from reference_masks import silhouette_rows, write_gray_png, write_manifest

import conftest

from viscoscope import engine, mantaflow
from viscoscope.mantaflow_calibration import export_surfaces
from viscoscope.operators import container, mantaflow_calibration, runner
from viscoscope.operators.identify import identify_dir

sys.path.insert(0, os.path.join(conftest.REPO, "sample_scenes"))
import _common  # noqa: E402

WIDTH, HEIGHT = 96, 64
FPS = 24
FRAMES = 16            # reference frames 1..FRAMES = simulation frames
FORMULA_SHARE = 0.4    # the Fluid Material's η makes the formula's value this share of the true one
RES_REFERENCE, RES_CALIBRATION = 28, 20
DENSITY = 1000.0
MASK_FRAMES = range(1, FRAMES + 1)
MASKS = ["masks/mask_%05d.png" % f for f in MASK_FRAMES]


def _column_scene(ctx, value_true=0.1):
    """A 6 cm liquid column on the ground (Viscoscope roles: ground, domain, liquid) with a Mantaflow
    liquid domain over the same box, the column its liquid flow, and a side camera."""
    scene = ctx.scene
    lo, hi = (-0.12, -0.12, 0.0), (0.12, 0.12, 0.12)
    container.add_domain(ctx, lo, hi)
    ground = bpy.data.objects.new("Ground", bpy.data.meshes.new("Ground"))
    ground.data.from_pydata([(-0.2, -0.2, 0), (0.2, -0.2, 0), (0.2, 0.2, 0), (-0.2, 0.2, 0)], [], [(0, 1, 2, 3)])
    scene.collection.objects.link(ground)
    ground.viscoscope.role = 'GROUND'
    bpy.ops.mesh.primitive_cube_add(size=0.06, location=(0.0, 0.0, 0.03))
    column = ctx.active_object
    column.name = "Liquid column"
    column.viscoscope.role = 'LIQUID'
    _common.make_flow(column, behavior='GEOMETRY')
    domain = _common.make_domain(scene, lo, hi, RES_CALIBRATION, 1 + FRAMES, name="Mantaflow Domain")
    domain.modifiers["Fluid"].domain_settings.use_collision_border_bottom = True
    bpy.ops.object.camera_add(location=(0.0, -0.45, 0.06), rotation=(math.radians(85), 0, 0))
    cam = ctx.active_object
    scene.camera = cam
    scene.viscoscope.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = WIDTH, HEIGHT, 100
    r.fps, r.fps_base = FPS, 1.0
    scene.frame_start, scene.frame_end = 1, 1 + FRAMES
    fluid = scene.viscoscope.fluid
    fluid.density = DENSITY
    # η whose formula value ν·0.4 s/L² is FORMULA_SHARE of the reference's viscosity_value.
    fluid.viscosity = FORMULA_SHARE * value_true * 0.24 ** 2 / 0.4 * DENSITY
    ctx.view_layer.objects.active = domain
    ctx.view_layer.update()
    return domain


def _bake_reference(ctx, engine_path, domain, work, value_true):
    """Mantaflow at RES_REFERENCE and value_true → silhouettes in Identify's reference folder."""
    scene = ctx.scene
    ds = mantaflow.domain_settings(domain)
    ds.resolution_max = RES_REFERENCE
    ds.use_viscosity = True
    ds.viscosity_value = value_true
    ds.cache_type = 'ALL'
    ds.cache_directory = os.path.join(work, "reference_cache")
    ds.cache_frame_start, ds.cache_frame_end = scene.frame_start, scene.frame_start + FRAMES
    with ctx.temp_override(object=domain, active_object=domain, scene=scene):
        assert bpy.ops.fluid.bake_all() == {'FINISHED'}
    surfaces = os.path.join(work, "reference_surfaces")
    counts = export_surfaces(scene, domain, surfaces, FRAMES)
    assert all(counts), counts
    scene.frame_set(scene.frame_start)
    camera_json = os.path.join(work, "reference_camera.json")
    from viscoscope import scene_export
    scene_export.export_camera(scene.camera, scene, camera_json)
    empty = os.path.join(work, "empty")
    os.makedirs(os.path.join(empty, "masks"))
    for f in range(1, FRAMES + 1):
        write_gray_png(os.path.join(empty, "masks", "mask_%05d.png" % f), [[0] * WIDTH for _ in range(HEIGHT)])
    write_manifest(empty, MASK_FRAMES, FPS, (WIDTH, HEIGHT), MASKS, "empty")
    proc = subprocess.run([engine_path, "score", "--camera", camera_json, "--reference", empty, "--sim", surfaces,
                           "--sim-first", "1", "--out", os.path.join(work, "reference_score"), "--progress", "none"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    reference = os.path.join(identify_dir(scene), "out", "reference")
    os.makedirs(os.path.join(reference, "masks"))
    areas = []
    for f in range(1, FRAMES + 1):
        rows = silhouette_rows(os.path.join(work, "reference_score", "diff_%05d.png" % f))
        areas.append(sum(v > 0 for row in rows for v in row))
        write_gray_png(os.path.join(reference, "masks", "mask_%05d.png" % f), rows)
    write_manifest(reference, MASK_FRAMES, FPS, (WIDTH, HEIGHT), MASKS,
                   "mantaflow at viscosity_value %g, resolution %d" % (value_true, RES_REFERENCE))
    # The column is seen and it slumps: its silhouette widens from the first frame to the last (by
    # 1.11 × at 0.1, 1.8 × at 0.02).
    assert all(30 < a < WIDTH * HEIGHT // 2 for a in areas), areas
    assert areas[-1] > 1.05 * areas[0], areas
    ds.resolution_max = RES_CALIBRATION  # frees the reference's bake
    return areas


@pytest.mark.slow
@pytest.mark.engine
@pytest.mark.parametrize("value_true", [0.02, 0.1])
def test_calibration_finds_the_reference_viscosity_value(ctx, tmp_work, engine_path, use_engine, monkeypatch,
                                                          press_cancel, value_true):
    t0 = time.monotonic()
    use_engine(engine_path)
    monkeypatch.setattr(bpy.context.preferences.addons["viscoscope"].preferences, "threads", 2)
    domain = _column_scene(ctx, value_true)
    work = str(tmp_work)
    areas = _bake_reference(ctx, engine_path, domain, work, value_true)
    t_reference = time.monotonic() - t0
    vs = ctx.scene.viscoscope
    formula, _ = mantaflow_calibration.formula_value(ctx, domain)
    assert formula == pytest.approx(FORMULA_SHARE * value_true, rel=1e-4)

    # Press Cancel once the third bake is under way.
    st = vs.calibrate_job
    statuses, jobs = press_cancel("calibrate", lambda status: status.status.startswith("Bake 3/"))
    assert bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT') == {'CANCELLED'}
    assert jobs[0].returncode == engine.EXIT_CANCELLED, jobs[0].stderr
    assert st.can_resume and st.status == "Cancelled; Resume continues" and not st.running
    out_dir = os.path.join(mantaflow_calibration.calibration_dir(ctx.scene), "out")
    assert not os.path.exists(os.path.join(out_dir, "calibration.json"))
    finished = [d for d in os.listdir(os.path.join(out_dir, "bakes"))
                if os.path.isfile(os.path.join(out_dir, "bakes", d, "bake.json"))]
    assert len(finished) == 2, finished

    # Run again: the two finished bakes are reused, the rest baked.
    t_start = time.monotonic()
    assert bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT') == {'FINISHED'}, st.error
    t_calibration = time.monotonic() - t_start
    assert st.status == "Done" and not st.error, (st.status, st.error)
    doc = json.load(open(os.path.join(out_dir, "calibration.json")))
    values = {v["viscosity_value"]: v["E"] for v in doc["values"]}
    assert sum(v["reused"] for v in doc["values"]) == 2, doc["values"]
    chosen = doc["chosen_value"]
    assert doc["formula_value"] == pytest.approx(formula) and doc["resolution"] == RES_CALIBRATION
    assert chosen == min(values, key=values.get) and doc["ratio"] == pytest.approx(chosen / formula)
    # The known value is bracketed by values tried, and the chosen one lies within a factor of 2 of it.
    assert min(values) < value_true < max(values), values
    assert abs(math.log(chosen / value_true)) < math.log(2.0), (chosen, values)
    # E falls towards the chosen value from both ends of what was tried.
    assert values[min(values)] > values[chosen] < values[max(values)], values
    # The domain took the calibrated value; the panel's summary matches the file.
    ds = mantaflow.domain_settings(domain)
    assert ds.use_viscosity and ds.viscosity_value == pytest.approx(chosen, rel=1e-6)
    summary = json.loads(vs.mantaflow_calibration)
    assert summary["chosen_value"] == chosen and summary["formula_value"] == doc["formula_value"]
    assert [v for v, _E in summary["values"]] == sorted(values)
    # Progress went through the bakes as the panel shows it.
    shown = [(p, s) for n, p, s in statuses if n == 2 and s.startswith("Bake ")]
    assert shown and "viscosity_value" in shown[0][1], statuses[:5]
    assert 0.0 <= shown[0][0] < shown[-1][0] <= 100.0, shown
    assert any("Frame " in s for _p, s in shown), shown

    # A third run reuses every bake and chooses the same value.
    t_again = time.monotonic()
    assert bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT') == {'FINISHED'}, st.error
    again = json.load(open(os.path.join(out_dir, "calibration.json")))
    assert again["chosen_value"] == chosen and all(v["reused"] for v in again["values"]), again["values"]
    print("\n[mantaflow_calibration] reference areas %s; formula %.4g, chosen %.4g (truth %.3g), E %s; "
          "reference %.1f s, calibration after cancel %.1f s (%d bakes), rerun %.1f s"
          % (areas, formula, chosen, value_true, {"%.4g" % v: round(e, 4) for v, e in sorted(values.items())},
             t_reference, t_calibration, len(values), time.monotonic() - t_again))


def test_calibration_without_reference_says_so_in_one_line(ctx, tmp_work, fake_engine, use_engine):
    use_engine(fake_engine)
    _column_scene(ctx)
    st = ctx.scene.viscoscope.calibrate_job
    with pytest.raises(RuntimeError, match="no reference silhouettes"):  # the operator's error report
        bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT')
    assert st.error == "no reference silhouettes: run Identify or Preview Silhouettes first"
    assert not runner.is_running("calibrate")


def test_calibration_without_a_mantaflow_domain_says_so_in_one_line(ctx, tmp_work, fake_engine, use_engine):
    use_engine(fake_engine)
    domain = _column_scene(ctx)
    bpy.data.objects.remove(domain)
    st = ctx.scene.viscoscope.calibrate_job
    with pytest.raises(RuntimeError, match="no Mantaflow liquid domain"):
        bpy.ops.viscoscope.calibrate_mantaflow('EXEC_DEFAULT')
    assert st.error.startswith("no Mantaflow liquid domain in the scene") and "\n" not in st.error


@pytest.mark.engine
def test_driver_bad_input_is_one_line_and_exit_2(ctx, tmp_work, engine_path):
    """The driver itself, on a .blend without the named domain and on a reference with no manifest."""
    _column_scene(ctx)
    work = str(tmp_work)
    blend = os.path.join(work, "copy.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    for name in ("camera.json", "scene.json"):
        with open(os.path.join(work, name), "w") as fh:
            json.dump({}, fh)
    os.makedirs(os.path.join(work, "reference"))

    def run(domain, reference):
        args = mantaflow_calibration.driver_args(engine_path, blend, domain, reference,
                                                 os.path.join(work, "camera.json"), os.path.join(work, "scene.json"),
                                                 0.1, os.path.join(work, "out"), 0.0)
        return subprocess.run(args, capture_output=True, text=True, timeout=120)
    proc = run("Mantaflow Domain", os.path.join(work, "reference"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("error: reference silhouettes not found: ")
    assert "Traceback" not in proc.stderr
    write_manifest(os.path.join(work, "reference"), MASK_FRAMES, FPS, (WIDTH, HEIGHT), MASKS, "test")
    proc = run("Liquid column", os.path.join(work, "reference"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "error: 'Liquid column' is not a Mantaflow liquid domain"
    assert "Traceback" not in proc.stderr


def test_calibration_progress_is_shown_per_bake(addon):
    from viscoscope import engine
    event = {"event": "progress", "stage": "bake", "bake": 2, "bakes": 4, "viscosity_value": 0.25,
             "frame": 5, "frames": 10, "best_value": 0.1, "best_E": 0.3}
    assert engine.progress_fraction(event) == pytest.approx((1 + 0.5) / 4)
    assert runner.describe_progress(event) == "Bake 2/4: viscosity_value 0.25 · Frame 5/10 · best 0.1 · best E 0.3"
    scoring = dict(event, stage="score", frame=10)
    assert engine.progress_fraction(scoring) == pytest.approx(2 / 4)
    assert runner.describe_progress(scoring).startswith("Bake 2/4: viscosity_value 0.25 · scoring")


def test_panel_shows_the_calibration_and_what_it_cannot_match(ctx):
    from test_sidebar import _draw_all
    vs = ctx.scene.viscoscope
    vs.mantaflow_calibration = json.dumps({
        "domain": "Mantaflow Domain", "resolution": 48, "formula_value": 0.0992, "chosen_value": 0.397,
        "ratio": 4.0, "bracketed": True, "values": [[0.0248, 0.31], [0.0992, 0.2], [0.397, 0.05], [1.59, 0.12]],
        "warning": ""})
    text = "".join("".join(_draw_all(ctx.scene, 600)).split())
    for shown in ("Formula'sviscosity_value:0.0992", "Calibrated:0.397,4×theformula's", "0.0248:E0.31",
                  "0.397:E0.05", "1.59:E0.12"):
        assert shown in text, text
    assert "shear-dependent" not in text
    vs.fluid.model = 'POWER_LAW'
    text = "".join("".join(_draw_all(ctx.scene, 600)).split())
    assert "Mantaflowhasnoshear-dependentviscosity:thecalibrationmatchesoneconstantviscositytothefootage" in text


def test_values_bracket_then_refine(addon):
    from viscoscope.mantaflow_calibration import next_values
    E = lambda v: abs(math.log(v / 0.3))  # noqa: E731  (a landscape with its minimum at 0.3)
    tried, refined, rounds = {}, 0, []
    queue = [0.1 * f for f in (0.25, 1.0, 4.0)]
    while queue:
        tried.update({v: E(v) for v in queue})
        queue, refining = next_values(tried, 4.0, refined, 2)
        refined += refining
        rounds.append(sorted(queue))
    best = min(tried, key=tried.get)
    # 0.4, the largest of the three, was best: one more step up brackets it; then ×/÷ 2 around the
    # best, then ×/÷ √2 around the new best, which lands within √2 of 0.3.
    assert rounds[0] == pytest.approx([1.6]) and rounds[1] == pytest.approx([0.2, 0.8])
    assert rounds[2] == pytest.approx([0.4 / 2 ** 0.5, 0.4 * 2 ** 0.5]) and rounds[3] == []
    assert len(tried) == 8 and abs(math.log(best / 0.3)) < math.log(2 ** 0.5)
    # A best at the edge is extended past first, up to Mantaflow's limit of 10.
    queue, refining = next_values({1.0: 3.0, 4.0: 2.0}, 4.0, 0, 2)
    assert queue == [10.0] and not refining
    assert next_values({4.0: 3.0, 10.0: 2.0}, 4.0, 0, 0) == ([], False)


def test_a_plateau_of_e_or_a_best_at_the_edge_is_warned_of(addon):
    from viscoscope.mantaflow_calibration import calibration_warnings
    # The capture cup at η = 3 Pa·s, 48 cells, diffusion off (tests/bench/FINDINGS.md): E within 3 %
    # of its least from 1.9 to 10.
    flat = {0.00372: 0.2923, 0.01488: 0.2111, 0.05952: 0.1620, 0.2381: 0.1096, 0.9524: 0.0718, 1.905: 0.0680,
            2.694: 0.0678, 3.81: 0.0676, 5.387: 0.0696, 7.619: 0.0696, 10.0: 0.0696}
    (warning,) = calibration_warnings(flat)
    assert warning.startswith("E is within 5 % of its least from 1.905 to 10")
    # The Mantaflow-against-Mantaflow test's landscape: a clear minimum, no warning.
    assert calibration_warnings({0.002: 0.3425, 0.008: 0.2864, 0.01131: 0.2677, 0.016: 0.2274, 0.02263: 0.1978,
                                 0.032: 0.2318, 0.064: 0.3335, 0.128: 0.425}) == []
    (warning,) = calibration_warnings({0.1: 0.3, 0.4: 0.2, 1.6: 0.1})
    assert warning.startswith("the best viscosity_value is the largest tried (1.6)")


def test_reference_frames_map_to_simulation_frames_as_identify_maps_them(addon):
    from viscoscope.mantaflow_calibration import BadInput, frame_mapping
    manifest = {"frames": [0, 1, 2, 3, 4], "times_s": [0, 0.1, 0.2, 0.3, 0.4], "weights": [0, 1, 1, 1, 1]}
    assert frame_mapping(manifest, 10.0, 0.0, 100) == (0, 4, [0.0, 1, 1, 1, 1])
    # A time offset moves the frames; past the scene's frame range they are left out.
    assert frame_mapping(manifest, 10.0, 0.5, 2) == (5, 7, [0.0, 1, 1, 0.0, 0.0])
    with pytest.raises(BadInput, match="consecutive"):
        frame_mapping(manifest, 20.0, 0.0, 100)
    with pytest.raises(BadInput, match="no reference frame"):
        frame_mapping(dict(manifest, weights=[0] * 5), 10.0, 0.0, 100)

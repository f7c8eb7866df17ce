"""Identify end to end through the real engine: the add-on's operator, its progress, Cancel
(SIGTERM → exit 3, checkpoint kept), Resume, and the result loaded into the Results section.

The reference avoids the inverse crime: the same Blender scene is simulated by the engine at another
resolution, particle seed and viscosity than the identification uses, and the engine's own exact
silhouettes (`score` against an empty reference, whose difference image is then the silhouette)
become the footage: a lossless video of bright liquid on a grey table after one empty frame, which
Identify extracts with the Silhouettes panel's settings like any clip."""

import json
import math
import os
import shutil
import subprocess
import time

import bpy
import pytest
from reference_masks import silhouette_rows, write_gray_png, write_manifest

from viscoscope import engine, scene_export
from viscoscope.operators import container, identify
from viscoscope.operators.identify import identify_dir

WIDTH, HEIGHT = 96, 64   # camera image (and reference masks), pixels
FPS = 10
FRAMES = (1, 2, 3)       # reference frames = simulation frames (Blender frame_start is time 0)
ETA_TRUE = 1.5           # Pa·s, the reference's viscosity
TABLE, LIQUID = 90, 220  # grey levels of the footage


def _make_reference(ctx, engine_path, work):
    """Simulate the scene at 16³, seed 7, η = ETA_TRUE and write its silhouettes as WORK/silhouettes."""
    vs = ctx.scene.viscoscope
    saved = (vs.sim_resolution, vs.sim_seed, vs.sim_frames, vs.fluid.viscosity)
    vs.sim_resolution, vs.sim_seed, vs.sim_frames, vs.fluid.viscosity = 16, 7, FRAMES[-1], ETA_TRUE
    ref = os.path.join(work, "reference_sim")
    scene_export.export_scene(ctx.scene, os.path.join(ref, "scene.json"))
    scene_export.export_camera(ctx.scene.camera, ctx.scene, os.path.join(ref, "camera.json"))
    vs.sim_resolution, vs.sim_seed, vs.sim_frames, vs.fluid.viscosity = saved
    run = lambda *args: subprocess.run([engine_path, *args], capture_output=True, text=True, timeout=60)  # noqa: E731
    proc = run("simulate", os.path.join(ref, "scene.json"), "--out", os.path.join(ref, "sim"), "--progress", "none")
    assert proc.returncode == 0, proc.stderr
    # The engine's exact silhouettes of those frames: score them against an all-empty reference.
    empty = os.path.join(ref, "empty")
    os.makedirs(os.path.join(empty, "masks"))
    names = ["masks/mask_%05d.png" % f for f in FRAMES]
    for name in names:
        write_gray_png(os.path.join(empty, name), [[0] * WIDTH for _ in range(HEIGHT)])
    write_manifest(empty, FRAMES, FPS, (WIDTH, HEIGHT), names, "empty")
    proc = run("score", "--camera", os.path.join(ref, "camera.json"), "--reference", empty,
               "--sim", os.path.join(ref, "sim"), "--sim-first", str(FRAMES[0]), "--out", os.path.join(ref, "score"),
               "--progress", "none")
    assert proc.returncode == 0, proc.stderr
    footage = os.path.join(ref, "footage")
    os.makedirs(footage)
    write_gray_png(os.path.join(footage, "frame_00000.png"), [[TABLE] * WIDTH for _ in range(HEIGHT)])
    areas, masks = [], []
    for frame in FRAMES:
        rows = silhouette_rows(os.path.join(ref, "score", "diff_%05d.png" % frame))
        areas.append(sum(v > 0 for row in rows for v in row))
        masks.append(rows)
        write_gray_png(os.path.join(footage, "frame_%05d.png" % frame),
                        [[LIQUID if v else TABLE for v in row] for row in rows])
    video = os.path.join(work, "pour.mkv")
    subprocess.run(["ffmpeg", "-loglevel", "error", "-framerate", str(FPS), "-i",
                    os.path.join(footage, "frame_%05d.png"), "-c:v", "ffv1", video], check=True)
    # The liquid is seen, and it moves: the column slumps into a film about a cell thick at 16³, so
    # that a fifth or more of the first frame's pixels change by the last. (The film's edge now
    # shows, and the area grew from the first frame to the last, where the smoothed one shrank.)
    assert all(20 < a < WIDTH * HEIGHT // 2 for a in areas), areas
    changed = sum(a != b for row_a, row_b in zip(masks[0], masks[-1]) for a, b in zip(row_a, row_b))
    assert changed > 0.2 * areas[0], (changed, areas)
    return video, areas


def _capture_scene(ctx):
    """Cup (Add Cup), a liquid column on the ground beside it, and a side camera."""
    cup, _ground, _domain = container.add_cup(ctx, (0, 0, 0))
    cup.viscoscope.cup_hole_radius = 0.0  # the cup holds nothing, so its hole sets no grid size
    vs = ctx.scene.viscoscope
    vs.fill_volume = 0.0  # the liquid is the column below, not the cup's fill
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.075, 0.0, 0.03))
    liquid = ctx.active_object
    liquid.scale = (0.05, 0.05, 0.06)
    liquid.name = "Liquid column"
    liquid.viscoscope.role = 'LIQUID'
    bpy.ops.object.camera_add(location=(0.0, -0.45, 0.08), rotation=(math.radians(85), 0, 0))
    cam = ctx.active_object
    ctx.scene.camera = cam
    vs.camera = cam
    r = ctx.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = WIDTH, HEIGHT, 100
    r.fps, r.fps_base = FPS, 1.0
    ctx.scene.frame_start, ctx.scene.frame_end = 1, FRAMES[-1] + 1
    vs.fluid.density = 1400.0
    ctx.view_layer.update()


@pytest.mark.engine
def test_real_engine_identify_cancel_resume_and_results(ctx, tmp_work, engine_path, use_engine, monkeypatch, request,
                                                        press_cancel):
    if shutil.which("ffmpeg") is None:
        pytest.skip("ffmpeg is not installed")
    t0 = time.monotonic()
    out_dir = os.path.join(identify_dir(ctx.scene), "out")

    def forget_plots():  # later tests look plots up by name ("convergence.png")
        for img in [i for i in bpy.data.images if bpy.path.abspath(i.filepath).startswith(out_dir)]:
            bpy.data.images.remove(img)
    request.addfinalizer(forget_plots)
    use_engine(engine_path)
    monkeypatch.setattr(bpy.context.preferences.addons["viscoscope"].preferences, "threads", 2)
    _capture_scene(ctx)
    vs = ctx.scene.viscoscope
    work = str(tmp_work)
    video, areas = _make_reference(ctx, engine_path, work)
    vs.video_path = video
    vs.background, vs.clean_plate_frame = 'PLATE_FRAME', 0
    vs.identify_resolution = 12
    vs.max_generations = 3
    vs.eta_initial, vs.eta_spread = 4.0, 2.0
    vs.sim_seed = 1

    # Record what the scene's progress properties show at every poll, and press Cancel once a
    # progress update has arrived.
    st = vs.identify_job
    seen, jobs = press_cancel("identify", lambda status: status.progress > 0)

    t_start = time.monotonic()
    assert bpy.ops.viscoscope.identify('EXEC_DEFAULT') == {'CANCELLED'}
    first_run = time.monotonic() - t_start
    job_doc = json.load(open(os.path.join(identify_dir(ctx.scene), "job.json")))
    assert job_doc["video"] == video and "silhouettes" not in job_doc
    assert job_doc["resolution"] == 12 and job_doc["max_generations"] == 3
    # The engine extracted the clip with the panel's settings.
    extracted = json.load(open(os.path.join(out_dir, "reference", "manifest.json")))
    assert extracted["parameters"]["close_kernel_px"] == vs.close_diameter
    progress_1 = [(p, s) for n, p, s in seen if n == 1 and p > 0]
    assert progress_1, seen
    assert progress_1[0][1].startswith("Generation 1/3") and "best η" in progress_1[0][1], progress_1
    assert jobs[0].returncode == engine.EXIT_CANCELLED, jobs[0].stderr
    assert st.can_resume and st.status == "Cancelled; Resume continues" and not st.running
    assert st.out_dir == out_dir
    checkpoint = json.load(open(os.path.join(out_dir, "checkpoint.json")))
    done = checkpoint["cma"]["generation"]
    assert 1 <= done < 3, checkpoint["cma"]
    assert not os.path.exists(os.path.join(out_dir, "result.json"))
    assert vs.result_eta == 0.0

    t_resume = time.monotonic()
    assert bpy.ops.viscoscope.identify_resume('EXEC_DEFAULT') == {'FINISHED'}
    resume_run = time.monotonic() - t_resume
    assert len(jobs) == 2 and jobs[1].returncode == engine.EXIT_OK, jobs[1].stderr
    statuses_2 = [s for n, p, s in seen if n == 2 and s.startswith("Generation ")]
    assert statuses_2, seen
    # Resumed: the first generation it reports comes after the checkpointed ones.
    assert int(statuses_2[0].split()[1].split("/")[0]) == done + 1, statuses_2
    result = json.load(open(os.path.join(out_dir, "result.json")))
    eta, (low, high) = result["viscosity"]["value"], result["viscosity"]["interval"]
    assert st.status == "Done" and st.progress == pytest.approx(100.0) and not st.can_resume and not st.error
    assert vs.result_eta == pytest.approx(eta, rel=1e-6) and 1e-3 <= eta <= 1e4
    assert (vs.result_eta_low, vs.result_eta_high) == (pytest.approx(low, rel=1e-6), pytest.approx(high, rel=1e-6))
    assert vs.result_eta_low <= vs.result_eta <= vs.result_eta_high
    # η reaches the Fluid Material unless the engine (or a bound-reaching interval) casts doubt on it.
    doubts = (result.get("doubts") or []) + identify.bound_doubts(low, high)
    assert vs.result_doubts.splitlines() == doubts
    assert (vs.fluid.viscosity == pytest.approx(eta, rel=1e-6)) == (not doubts)
    for plot in ("convergence.png", "landscape.png"):  # drawn when the engine finds matplotlib
        if os.path.isfile(os.path.join(out_dir, plot)):
            assert any(bpy.path.abspath(i.filepath) == os.path.join(out_dir, plot) for i in bpy.data.images), plot
    print("\n[identify_real] areas %s; first run %.1f s (cancelled after %d generation(s)), resume %.1f s, "
          "η = %.4g [%.4g, %.4g] (truth %.3g), total %.1f s"
          % (areas, first_run, done, resume_run, eta, low, high, ETA_TRUE, time.monotonic() - t0))

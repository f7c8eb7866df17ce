"""The capture workflow's operators: reference video, camera match, identify (cancel + resume), results.

Most tests run the operators against the stand-in engine (conftest.FAKE_ENGINE), which speaks the
engine's progress / exit-code / checkpoint contract at a pace the test sets, so that Cancel lands
mid-run; those marked `engine` use the real one (extraction, the camera match, a simulate run for
Load Hidden Fields, and the extraction Identify starts with). A whole identification through the
real engine is in test_identify_real.py and test_capture_identify.py."""

import json
import math
import os
import shutil
import subprocess
import time

import bpy
import pytest

from viscoscope import camera_math, scene_export
from viscoscope.operators import container, reference, runner, silhouettes


@pytest.fixture(scope="module")
def clip_path(tmp_path_factory):
    """A 12-frame 160x120 video at 25 fps (ffmpeg's test pattern)."""
    if shutil.which("ffmpeg") is None:
        pytest.skip("ffmpeg is not installed")
    path = tmp_path_factory.mktemp("video") / "pour.mp4"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-f", "lavfi", "-i", "testsrc=size=160x120:rate=25",
                    "-frames:v", "12", "-pix_fmt", "yuv420p", str(path)], check=True)
    return str(path)



# The sample cup's rim and base, left and right: points whose world position an artist knows.
RIM_AND_BASE = ((-0.046, 0, 0.114), (0.046, 0, 0.114), (-0.046, 0, 0.05), (0.046, 0, 0.05))


def _mark_points(ctx, cam, worlds, scale=1):
    """Camera points at `worlds`, marked where `cam` sees them (× scale); returns that camera (OpenCV)."""
    ctx.view_layer.update()
    truth = camera_math.opencv_camera(scene_export.camera_dict(cam, ctx.scene))
    for world in worlds:
        p = ctx.scene.viscoscope.points.add()
        p.label = "p%d" % len(ctx.scene.viscoscope.points)
        p.world = world
        p.image = [scale * c for c in camera_math.project(truth, world)]
    return truth

def _capture(ctx):
    container.add_cup(ctx, (0, 0, 0))
    bpy.ops.object.camera_add(location=(0, -0.45, 0.12), rotation=(math.radians(83), 0, 0))
    ctx.active_object.name = "Viscoscope camera"
    ctx.scene.camera = ctx.active_object
    ctx.scene.viscoscope.camera = ctx.active_object
    return ctx.active_object


def test_load_video_matches_scene_and_sets_background(ctx, clip_path):
    cam = _capture(ctx)
    ctx.scene.render.fps = 24
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    vs = ctx.scene.viscoscope
    assert vs.clip is not None and ctx.scene.active_clip == vs.clip
    assert (ctx.scene.frame_start, ctx.scene.frame_end) == (1, 12)
    assert ctx.scene.render.fps / ctx.scene.render.fps_base == pytest.approx(25.0)
    assert (ctx.scene.render.resolution_x, ctx.scene.render.resolution_y) == (160, 120)
    assert cam.data.show_background_images
    assert cam.data.background_images[0].source == 'MOVIE_CLIP' and cam.data.background_images[0].clip == vs.clip


@pytest.mark.parametrize("path, message", [("", "No video chosen"), ("/nonexistent/pour.mp4", "Video not found")])
def test_load_video_errors(ctx, path, message):
    with pytest.raises(ValueError, match=message):
        reference.load_reference(ctx, path)


def test_load_video_not_a_video(ctx, tmp_path):
    bad = tmp_path / "notes.mp4"
    bad.write_text("not a video")
    with pytest.raises(ValueError, match="Cannot (read|decode) video"):
        reference.load_reference(ctx, str(bad))


def test_match_camera_from_points(ctx, tmp_work, fake_engine, use_engine, monkeypatch, tmp_path):
    """The operator writes the points, runs convert + pnp, and places the camera from R, t."""
    use_engine(fake_engine)
    cam = _capture(ctx)
    truth = _mark_points(ctx, cam, RIM_AND_BASE + ((0, 0.046, 0.114),))
    result = tmp_path / "pnp.json"
    result.write_text(json.dumps(truth))
    monkeypatch.setenv("FAKE_PNP_RESULT", str(result))
    expected = cam.matrix_world.copy()
    cam.location = (1, 2, 3)
    cam.rotation_euler = (0, 0, 0)
    assert bpy.ops.viscoscope.match_camera() == {'FINISHED'}
    for i in range(4):
        for j in range(4):
            assert cam.matrix_world[i][j] == pytest.approx(expected[i][j], abs=1e-5)
    assert ctx.scene.viscoscope.reprojection_error == pytest.approx(0.0, abs=1e-3)
    points = json.load(open(os.path.join(str(tmp_work), "camera", "points.json")))
    assert len(points["world"]) == 5 and points["world"][0] == pytest.approx([-0.046, 0, 0.114])


def test_match_camera_needs_four_points(ctx, tmp_work):
    _capture(ctx)
    with pytest.raises(RuntimeError, match="mark at least 4 points, 0 marked"):
        bpy.ops.viscoscope.match_camera()


def test_identify_cancel_resume_and_results(ctx, tmp_work, fake_engine, use_engine, clip_path, monkeypatch):
    use_engine(fake_engine)
    _capture(ctx)
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    vs = ctx.scene.viscoscope
    vs.max_generations = 40
    vs.grid_placements = 2
    vs.placement_schedule = 'each_evaluation'
    monkeypatch.setenv("FAKE_ENGINE_SLEEP", "0.05")
    from viscoscope.operators.identify import VISCOSCOPE_OT_identify, identify_dir
    args, out_dir = VISCOSCOPE_OT_identify.prepare(VISCOSCOPE_OT_identify, ctx)
    job = json.load(open(os.path.join(identify_dir(ctx.scene), "job.json")))
    assert job["format"] == "viscoscope.job" and job["max_generations"] == 40 and job["grid_placements"] == 2
    # The video and the panel's extraction settings, never the Preview's masks.
    assert job["video"] == clip_path and "silhouettes" not in job
    assert job["extraction"] == silhouettes.extraction_settings(ctx.scene)
    assert job["grid_placement_schedule"] == "each_evaluation"
    assert job["parameters"][0]["initial"] == pytest.approx(5.0)
    assert os.path.isfile(os.path.join(identify_dir(ctx.scene), job["scene"]))
    runner.start(ctx, "identify", args, out_dir, lambda c, d: None)
    deadline = 200
    while runner.pump(ctx, "identify") == 'RUNNING' and vs.identify_job.progress < 10 and deadline:
        deadline -= 1
        import time
        time.sleep(0.02)
    st = vs.identify_job
    assert st.status.startswith("Generation ") and "best η" in st.status and "best E" in st.status
    assert runner.cancel("identify")
    while runner.pump(ctx, "identify") == 'RUNNING':
        pass
    assert st.can_resume and st.status.startswith("Cancelled")
    assert vs.result_eta == 0.0
    # Resume continues from the checkpoint and loads the result.
    assert bpy.ops.viscoscope.identify_resume('EXEC_DEFAULT') == {'FINISHED'}
    starts = [int(x) for x in open(os.path.join(out_dir, "starts.txt")).read().split()]
    assert starts[0] == 0 and 0 < starts[1] < 40
    assert vs.result_eta == pytest.approx(7.9)
    assert (vs.result_eta_low, vs.result_eta_high) == (pytest.approx(7.5), pytest.approx(8.3))
    assert vs.fluid.viscosity == pytest.approx(7.9)
    assert st.status == "Done" and not st.can_resume


def test_identify_without_video_is_a_clear_error(ctx, tmp_work, fake_engine, use_engine):
    use_engine(fake_engine)
    _capture(ctx)
    with pytest.raises(RuntimeError, match="no reference video"):
        bpy.ops.viscoscope.identify('EXEC_DEFAULT')


def test_resume_without_a_previous_run(ctx, tmp_work, fake_engine, use_engine, clip_path):
    use_engine(fake_engine)
    _capture(ctx)
    ctx.scene.viscoscope.video_path = clip_path
    with pytest.raises(RuntimeError, match="nothing to resume"):
        bpy.ops.viscoscope.identify_resume('EXEC_DEFAULT')


def test_identify_result_plots_are_loaded(ctx, tmp_work, fake_engine, use_engine, clip_path):
    use_engine(fake_engine)
    _capture(ctx)
    ctx.scene.viscoscope.video_path = clip_path
    ctx.scene.viscoscope.max_generations = 3
    assert bpy.ops.viscoscope.identify('EXEC_DEFAULT') == {'FINISHED'}
    # The sample cup's hole needs a finer grid than the panel's default: the job has it, the panel says so.
    job = json.load(open(os.path.join(str(tmp_work), "identify", "job.json")))
    assert job["resolution"] > ctx.scene.viscoscope.identify_resolution
    assert ctx.scene.viscoscope.identify_job.note.startswith("Resolution %d used" % job["resolution"])
    img = bpy.data.images.get("convergence.png")
    assert img is not None and tuple(img.size) == (8, 6)


def test_preview_silhouettes_overlays_masks(ctx, tmp_work, fake_engine, use_engine, clip_path, monkeypatch):
    use_engine(fake_engine)
    cam = _capture(ctx)
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    ctx.scene.viscoscope.background = 'LEADING_FRAMES'
    ctx.scene.viscoscope.background_frames = 3
    monkeypatch.setenv("FAKE_ENGINE_FRAMES", "12")
    assert bpy.ops.viscoscope.preview_silhouettes('EXEC_DEFAULT') == {'FINISHED'}
    manifest = json.load(open(os.path.join(str(tmp_work), "silhouettes", "manifest.json")))
    i = manifest["options"].index("--background-frames")
    assert manifest["options"][i + 1] == "3"
    overlay = [b for b in cam.data.background_images if b.source == 'IMAGE']
    assert len(overlay) == 1 and overlay[0].image.source == 'SEQUENCE'
    assert overlay[0].image_user.frame_duration == 12 and overlay[0].display_depth == 'FRONT'
    assert [b.source for b in cam.data.background_images].count('MOVIE_CLIP') == 1


def test_preview_silhouettes_without_video(ctx, tmp_work, fake_engine, use_engine):
    use_engine(fake_engine)
    _capture(ctx)
    with pytest.raises(RuntimeError, match="reference video not found: none chosen"):
        bpy.ops.viscoscope.preview_silhouettes('EXEC_DEFAULT')


@pytest.mark.engine
def test_load_hidden_fields_from_engine_output(ctx, tmp_work, engine_path):
    """"Load hidden fields" imports an engine .vdb sequence (a simulate run stands in for identify's best run)."""
    container.add_cup(ctx, (0, 0, 0))
    ctx.scene.viscoscope.sim_resolution = 16
    ctx.scene.viscoscope.sim_frames = 3
    scene_path = os.path.join(str(tmp_work), "scene.json")
    scene_export.export_scene(ctx.scene, scene_path)
    fields = os.path.join(str(tmp_work), "identify", "out", "fields")
    subprocess.run([engine_path, "simulate", scene_path, "--out", fields, "--progress", "none"], check=True)
    ctx.scene.viscoscope.identify_job.out_dir = os.path.dirname(fields)
    assert bpy.ops.viscoscope.load_fields() == {'FINISHED'}
    obj = bpy.data.objects["Viscoscope Hidden Fields"]
    vol = obj.modifiers[0].object.data
    vol.grids.load()
    assert {"surface", "velocity", "pressure"} <= {g.name for g in vol.grids}


@pytest.mark.engine
def test_real_engine_extract_and_overlay(ctx, tmp_work, engine_path, use_engine, clip_path):
    use_engine(engine_path)
    cam = _capture(ctx)
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    ctx.scene.viscoscope.background = 'LEADING_FRAMES'
    ctx.scene.viscoscope.background_frames = 3
    assert bpy.ops.viscoscope.preview_silhouettes('EXEC_DEFAULT') == {'FINISHED'}
    masks = os.listdir(os.path.join(str(tmp_work), "silhouettes", "masks"))
    assert len(masks) >= 1
    assert any(b.source == 'IMAGE' and b.image.source == 'SEQUENCE' for b in cam.data.background_images)


@pytest.mark.engine
def test_real_engine_match_camera_from_points(ctx, tmp_work, engine_path, use_engine):
    use_engine(engine_path)
    cam = _capture(ctx)
    _mark_points(ctx, cam, RIM_AND_BASE + ((0, 0.046, 0.114), (0, -0.046, 0.05)))
    expected = cam.matrix_world.copy()
    cam.location = (0.02, -0.5, 0.2)
    cam.rotation_euler = (math.radians(70), 0.05, 0.1)
    assert bpy.ops.viscoscope.match_camera() == {'FINISHED'}
    for i in range(3):
        for j in range(4):
            assert cam.matrix_world[i][j] == pytest.approx(expected[i][j], abs=1e-3)
    assert 0.0 <= ctx.scene.viscoscope.reprojection_error < 0.05
    # The panel shows the error the engine measured, not one the add-on recomputed.
    with open(os.path.join(str(tmp_work), "camera", "camera.json")) as fh:
        solved = json.load(fh)
    assert ctx.scene.viscoscope.reprojection_error == pytest.approx(solved["reprojection_error_px"], rel=1e-5)


def _plate_image(clip_path, folder):
    """The clip's first frame as a PNG: a clean plate 'photographed' with the same camera."""
    path = os.path.join(str(folder), "plate.png")
    subprocess.run(["ffmpeg", "-loglevel", "error", "-i", clip_path, "-frames:v", "1", path], check=True)
    return path


def _extracted_by_identify(ctx, engine_path, timeout=120):
    """Start the real engine's identify on the job the panel writes and stop it once it has extracted
    the video (OUT/reference/source.json, what it was extracted from, is written last); returns
    OUT/reference."""
    from viscoscope import engine
    from viscoscope.operators import identify

    def source():
        try:
            with open(os.path.join(reference_dir, "source.json")) as fh:
                return fh.read()
        except FileNotFoundError:
            return None
    folder = identify.identify_dir(ctx.scene)
    out_dir = os.path.join(folder, "out")
    reference_dir = os.path.join(out_dir, "reference")
    before = source()
    job_path, _note = identify.write_job(ctx, folder)
    job = engine.EngineJob(engine.identify_args(engine_path, job_path, out_dir)).start()
    deadline = time.monotonic() + timeout
    while source() in (None, before) and not job.finished:
        assert time.monotonic() < deadline, "identify did not extract the video in %d s" % timeout
        time.sleep(0.1)
    job.kill()
    job.wait(30)
    assert source() not in (None, before), job.message()
    return reference_dir


@pytest.mark.engine
@pytest.mark.parametrize("background", ['LEADING_FRAMES', 'PLATE_IMAGE', 'PLATE_FRAME'])
def test_real_engine_preview_and_identify_extract_alike(ctx, tmp_work, engine_path, use_engine, clip_path,
                                                        background):
    """Preview Silhouettes and Identify extract the clip with the same settings, the panel's, into the
    same masks; a preview made before the settings changed is flagged, and Identify extracts again."""
    use_engine(engine_path)
    _capture(ctx)
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    vs = ctx.scene.viscoscope
    vs.background = background
    vs.background_frames = 2
    vs.clean_plate_frame = 1
    vs.clean_plate_image = _plate_image(clip_path, tmp_work)
    vs.close_diameter, vs.min_blob, vs.mask_threshold, vs.var_threshold = 3, 7, 100, 20.0
    assert bpy.ops.viscoscope.preview_silhouettes('EXEC_DEFAULT') == {'FINISHED'}, vs.extract_job.error
    preview = json.load(open(os.path.join(str(tmp_work), "silhouettes", "manifest.json")))
    params = preview["parameters"]
    assert (params["close_kernel_px"], params["min_blob_px"], params["threshold"]) == (3, 7, 100)
    assert params["mog2_variance_threshold"] == pytest.approx(20.0)
    assert (params["background"] == "leading_frames") == (background == 'LEADING_FRAMES')
    assert vs.preview_made_with == silhouettes.made_with(ctx.scene)

    reference_dir = _extracted_by_identify(ctx, engine_path)
    identified = json.load(open(os.path.join(reference_dir, "manifest.json")))
    assert identified["parameters"] == params
    assert identified["masks"] == preview["masks"]
    for name in preview["masks"]:
        with open(os.path.join(str(tmp_work), "silhouettes", name), "rb") as a, \
                open(os.path.join(reference_dir, name), "rb") as b:
            assert a.read() == b.read(), name

    # Other settings: the shown preview is stale (the panel says so), and Identify extracts anew.
    vs.close_diameter = 5
    assert vs.preview_made_with != silhouettes.made_with(ctx.scene)
    identified = json.load(open(os.path.join(_extracted_by_identify(ctx, engine_path), "manifest.json")))
    assert identified["parameters"]["close_kernel_px"] == 5


def test_preview_and_identify_read_one_settings_function(ctx, tmp_work, fake_engine, use_engine, clip_path):
    """The Preview's command line is the job's "extraction" object, option for option."""
    from viscoscope import engine
    use_engine(fake_engine)
    _capture(ctx)
    assert bpy.ops.viscoscope.load_video(filepath=clip_path) == {'FINISHED'}
    settings = silhouettes.extraction_settings(ctx.scene)
    assert settings["clean_plate_frame"] == 0 and "background_frames" not in settings  # the default
    args = engine.extract_args("viscoscope", clip_path, "out", settings)
    for key, value in settings.items():
        i = args.index(engine.EXTRACT_OPTIONS[key])
        assert args[i + 1] == str(value), key
    ctx.scene.viscoscope.background = 'PLATE_IMAGE'
    with pytest.raises(scene_export.ExportError, match="clean plate image not found: none chosen"):
        silhouettes.extraction_settings(ctx.scene)


def _write_result(folder, value, interval, **extra):
    os.makedirs(str(folder), exist_ok=True)
    with open(os.path.join(str(folder), "result.json"), "w") as fh:
        json.dump(dict({"viscosity": {"value": value, "interval": interval}}, **extra), fh)


def test_doubtful_result_waits_for_apply_anyway(ctx, tmp_path):
    """result.json's "doubts" (the engine's reasons to distrust η) keep η out of the Fluid Material
    until Apply Anyway."""
    from viscoscope.operators import identify
    vs = ctx.scene.viscoscope
    vs.fluid.viscosity = 8.0
    vs.video_path = "//footage/honey_drip.mp4"
    doubts = ["viscosity: E varies by 0.4 % over the search, nearly flat", "frame 12: reference liquid no θ can put"]
    _write_result(tmp_path, 3.0, [2.5, 3.5], doubts=doubts)
    identify.read_result(ctx, str(tmp_path))
    vs.video_path = "//footage/another_liquid.mp4"  # loaded since: the result is still the first one's
    assert vs.result_eta == pytest.approx(3.0) and vs.fluid.viscosity == pytest.approx(8.0)
    assert vs.result_doubts.splitlines() == doubts and not vs.result_applied
    assert vs.fluid.identified_from == ""
    assert bpy.ops.viscoscope.apply_result() == {'FINISHED'}
    assert vs.fluid.viscosity == pytest.approx(3.0) and vs.result_applied
    assert vs.fluid.identified_from == ("honey_drip.mp4: η 3 Pa·s, interval 2.5–3.5 Pa·s, "
                                        "applied despite the engine's doubts")
    assert not bpy.ops.viscoscope.apply_result.poll()


@pytest.mark.parametrize("extra", [{}, {"doubts": []}], ids=["older engine", "no doubts"])
def test_result_without_doubts_sets_the_material(ctx, tmp_path, extra):
    from viscoscope.operators import identify
    vs = ctx.scene.viscoscope
    vs.video_path = "//footage/honey_drip.mp4"
    _write_result(tmp_path, 3.0, [2.5, 3.5], **extra)
    identify.read_result(ctx, str(tmp_path))
    assert vs.fluid.viscosity == pytest.approx(3.0) and vs.result_applied and vs.result_doubts == ""
    # The material says where η came from (a preset keeps it) until η is set otherwise.
    assert vs.fluid.identified_from == "honey_drip.mp4: η 3 Pa·s, interval 2.5–3.5 Pa·s"
    vs.fluid.viscosity = 4.0
    assert vs.fluid.identified_from == ""


@pytest.mark.parametrize("bound_end", [0, 1])
def test_interval_reaching_a_search_bound_is_flagged(ctx, tmp_work, clip_path, bound_end):
    """Whatever the engine says, an interval ending on the job's search bound is flagged, and η waits."""
    from viscoscope.operators import identify
    _capture(ctx)
    ctx.scene.viscoscope.video_path = clip_path
    job_path, _note = identify.write_job(ctx, identify.identify_dir(ctx.scene))
    bounds = json.load(open(job_path))["parameters"][0]
    bound = (bounds["min"], bounds["max"])[bound_end]
    interval = [bound, bound * 3] if bound_end == 0 else [bound / 3, bound]
    vs = ctx.scene.viscoscope
    vs.fluid.viscosity = 8.0
    _write_result(tmp_work / "out", interval[1 - bound_end], interval)
    identify.read_result(ctx, str(tmp_work / "out"))
    assert "search bound" in vs.result_doubts and not vs.result_applied
    assert vs.fluid.viscosity == pytest.approx(8.0)


def test_match_camera_refuses_points_outside_the_image(ctx, tmp_work):
    """Pixels marked on a bigger image than the camera's (the sample's 1280 × 720 points on its
    320 × 180 clip) are refused before any solve."""
    cam = _capture(ctx)
    ctx.scene.render.resolution_x, ctx.scene.render.resolution_y = 320, 180
    _mark_points(ctx, cam, RIM_AND_BASE, scale=4)
    before = cam.matrix_world.copy()
    with pytest.raises(RuntimeError, match=r"point 'p\d' at pixel \(\d+, \d+\) is outside the 320 × 180 image"):
        bpy.ops.viscoscope.match_camera()
    assert cam.matrix_world == before


@pytest.mark.engine
def test_real_engine_match_camera_refuses_a_pose_beyond_the_clip_range(ctx, tmp_work, engine_path, use_engine):
    """A solve that puts the points beyond the camera's clip_end (Blender would not draw them) is refused."""
    use_engine(engine_path)
    cam = _capture(ctx)
    _mark_points(ctx, cam, RIM_AND_BASE + ((0, 0.046, 0.114), (0, -0.046, 0.05)))
    cam.data.clip_end = 0.3  # the points are about 0.45 m away
    cam.location = (0.02, -0.5, 0.2)
    ctx.view_layer.update()
    before = cam.matrix_world.copy()
    with pytest.raises(RuntimeError, match=r"the points put the camera 0\.4\d+ m from them, outside its clip range"):
        bpy.ops.viscoscope.match_camera()
    assert cam.matrix_world == before

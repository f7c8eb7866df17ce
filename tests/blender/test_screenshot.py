"""A real Blender window under Xvfb shows the Viscoscope tab on the sample capture scene.

The screenshot is kept as an artifact in $VISCOSCOPE_ARTIFACTS (CTest sets it to the build folder)."""

import json
import os
import shutil
import subprocess

import bpy
import pytest

import conftest

pytestmark = pytest.mark.gui

PANELS = ["VIEW3D_PT_viscoscope_%s" % n for n in
          ("reference", "camera", "container", "silhouettes", "identify", "results", "diagnose", "fluid", "transfer")]


def _artifacts(tmp_path):
    folder = os.environ.get("VISCOSCOPE_ARTIFACTS") or str(tmp_path)
    os.makedirs(folder, exist_ok=True)
    return folder


def _run_window(command, out, tmp_path):
    """Runs Blender's window, which writes `out` and its report; once more if Blender itself crashed
    (it left a crash log), with nothing of the first run's kept but its log.

    Blender 3.4 under Xvfb with simulated events crashed once in a CI run, inside its own layout code
    (the crash log's Python frame: a panel's `layout.row()`), and not in 12 runs here. A second crash
    fails the test; the first one's log is kept beside the screenshot either way."""
    crash_logs = []
    for attempt in range(2):
        for stale in (out, os.path.splitext(out)[0] + ".json"):
            if os.path.exists(stale):
                os.remove(stale)
        temp = tmp_path / ("blender_tmp_%d" % attempt)  # where Blender writes <blend>.crash.txt
        temp.mkdir()
        proc = subprocess.run(command, capture_output=True, text=True, timeout=400, env=dict(os.environ, TMPDIR=str(temp)))
        logs = sorted(temp.glob("*.crash.txt"))
        for log in logs:
            kept = os.path.join(_artifacts(tmp_path), "viscoscope_panel_crash_%d.txt" % attempt)
            shutil.copyfile(log, kept)
            crash_logs.append("\n%s:\n%s" % (kept, log.read_text()[-1500:]))
        if not logs or attempt == 1:
            break
        print("Blender crashed (exit %s), log kept: running the window once more" % proc.returncode)
    return proc, "".join(crash_logs)


def test_panel_screenshot_under_xvfb(tmp_path):
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run is not installed")
    blender = bpy.app.binary_path
    blend_dir = tmp_path / "scene"
    build = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                            os.path.join(conftest.REPO, "sample_scenes", "capture_scene.py"), "--",
                            "--out", str(blend_dir)], capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-2000:]
    blend = blend_dir / "capture.blend"
    out = os.path.join(_artifacts(tmp_path), "viscoscope_panel.png")
    # With an engine, also run "Simulate with Viscoscope" through its modal operator in the window.
    simulate = ["--simulate"] if os.environ.get("VISCOSCOPE_ENGINE") else []
    command = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", blender, "--factory-startup",
               "--enable-event-simulate", "--window-geometry", "0", "0", "1600", "1000", str(blend),
               "--python", os.path.join(conftest.HERE, "screenshot_panel.py"), "--", out, *simulate]
    proc, crashes = _run_window(command, out, tmp_path)
    assert os.path.isfile(out), "no screenshot (exit %s): %s%s" % (proc.returncode, proc.stderr[-2000:], crashes)
    with open(os.path.splitext(out)[0] + ".json") as fh:
        report = json.load(fh)
    assert report["log"] == [], report["log"]
    assert report["registered"]
    assert set(PANELS) <= set(report["drawn"]), report["drawn"]
    if simulate:
        sim = report["simulation"]
        assert sim["invoke_result"] == ["RUNNING_MODAL"]  # returned at once, the engine runs outside
        assert sim["status"] == "Done" and sim["error"] == "", sim
        assert sim["imported"]
        # The panel showed the engine's progress while it ran. How many values it caught depends on how
        # fast the window redraws against the engine, i.e. on the machine's load (a loaded run caught
        # only 0 and 53.3 % of 30 frames): one between 0 and 100 is what does not depend on it.
        assert any(0 < p < 100 for p in sim["progress_seen"]), sim["progress_seen"]
        # Blender's main loop kept running while the engine worked (generous: CI machines are slow).
        assert sim["max_gap"] < 5.0, sim["max_gap"]
        assert os.path.isfile(sim["running_screenshot"])

    img = bpy.data.images.load(out)
    try:
        assert tuple(img.size) == (1600, 1000)
        px = list(img.pixels)
        lum = [0.3 * px[i] + 0.59 * px[i + 1] + 0.11 * px[i + 2] for i in range(0, len(px), 4 * 97)]
        mean = sum(lum) / len(lum)
        var = sum((l - mean) ** 2 for l in lum) / len(lum)
        assert var > 1e-3, "the screenshot is blank (variance %g)" % var
        assert len({round(l, 2) for l in lum}) > 20
    finally:
        bpy.data.images.remove(img)

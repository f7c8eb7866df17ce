"""Shared fixtures: the add-on enabled as the package "viscoscope", a fresh scene, the engine."""

import os
import sys
import tempfile

import pytest

import addon_utils
import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
ADDON_SRC = os.path.join(REPO, "addon")
MODULE = "viscoscope"

_link_dir = tempfile.mkdtemp(prefix="viscoscope_addon_")
# Presets are written to the user's config: point it at a throw-away folder for the tests.
os.environ["BLENDER_USER_SCRIPTS"] = tempfile.mkdtemp(prefix="viscoscope_user_scripts_")
os.symlink(ADDON_SRC, os.path.join(_link_dir, MODULE))
sys.path.insert(0, _link_dir)


def enable_addon():
    mod = addon_utils.enable(MODULE, default_set=True, handle_error=None)
    assert mod is not None, "the add-on failed to enable"
    return mod


def disable_addon():
    addon_utils.disable(MODULE, default_set=True, handle_error=None)


@pytest.fixture(scope="session")
def addon():
    mod = enable_addon()
    yield mod
    disable_addon()


@pytest.fixture
def scene(addon):
    """The context scene, emptied and reset to defaults (metres, 24 fps)."""
    sc = bpy.context.scene
    for obj in list(sc.objects):
        bpy.data.objects.remove(obj)
    sc.property_unset("viscoscope")
    sc.unit_settings.system = 'METRIC'
    sc.unit_settings.scale_length = 1.0
    sc.render.fps, sc.render.fps_base = 24, 1.0
    sc.frame_start, sc.frame_end = 1, 250
    sc.use_gravity = True
    sc.gravity = (0.0, 0.0, -9.81)
    yield sc
    for obj in list(sc.objects):
        bpy.data.objects.remove(obj)


@pytest.fixture
def ctx(scene):
    """bpy.context, whose scene is the reset test scene."""
    return bpy.context


@pytest.fixture
def engine_path():
    path = os.environ.get("VISCOSCOPE_ENGINE")
    if not path:
        pytest.skip("VISCOSCOPE_ENGINE is not set (build native/ and point it at build/bin/viscoscope)")
    assert os.access(path, os.X_OK), "VISCOSCOPE_ENGINE=%s is not executable" % path
    return path


@pytest.fixture
def tmp_work(tmp_path, scene):
    scene.viscoscope.work_dir = str(tmp_path)
    return tmp_path


FAKE_ENGINE = r'''#!/usr/bin/python3
"""A stand-in engine speaking the engine's progress/exit-code contract (for runner tests)."""
import json, os, signal, sys, time
mode = os.environ.get("FAKE_ENGINE_MODE", "ok")
frames = int(os.environ.get("FAKE_ENGINE_FRAMES", "5"))
sleep = float(os.environ.get("FAKE_ENGINE_SLEEP", "0.05"))
cancelled = []
signal.signal(signal.SIGTERM, lambda *a: cancelled.append(1))
def write_png(path, w=8, h=6, value=255):
    import struct, zlib
    raw = b"".join(b"\x00" + bytes([value if (x + y) % 2 else 0 for x in range(w)]) for y in range(h))
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xffffffff)
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                 + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
if sys.argv[1:2] == ["--version"]:
    print("0.1.0"); sys.exit(0)
if mode == "bad":
    print("scene.json: material.viscosity must be >= 0", file=sys.stderr); sys.exit(2)
if sys.argv[1:3] == ["camera", "convert"]:
    sys.path.insert(0, os.environ["FAKE_ENGINE_ADDON"])
    import camera_math
    cam = json.load(open(sys.argv[3]))
    K, (w, h) = camera_math.intrinsics(cam)
    json.dump({"K": K, "width": w, "height": h}, open(sys.argv[sys.argv.index("--out") + 1], "w")); sys.exit(0)
if sys.argv[1:3] == ["camera", "pnp"]:
    solved = json.load(open(os.environ["FAKE_PNP_RESULT"]))
    json.dump(solved, open(sys.argv[sys.argv.index("--out") + 1], "w")); sys.exit(0)
out = sys.argv[sys.argv.index("--out") + 1]
os.makedirs(out, exist_ok=True)
if os.environ.get("FAKE_ENGINE_WARNING"):
    print(json.dumps({"event": "warning", "message": os.environ["FAKE_ENGINE_WARNING"]}), flush=True)
if sys.argv[1] == "extract":
    os.makedirs(os.path.join(out, "masks"), exist_ok=True)
    for f in range(1, frames + 1):
        write_png(os.path.join(out, "masks", "mask_%05d.png" % f))
        print(json.dumps({"event": "progress", "frame": f, "frames": frames}), flush=True)
    json.dump({"frames": frames, "options": sys.argv[sys.argv.index("json") + 1:]}, open(os.path.join(out, "manifest.json"), "w"))
    sys.exit(0)
if sys.argv[1] == "identify":
    job = json.load(open(sys.argv[2]))
    gens = job["max_generations"]
    ckpt = os.path.join(out, "checkpoint.json")
    start = json.load(open(ckpt))["generation"] if os.path.exists(ckpt) else 0
    with open(os.path.join(out, "starts.txt"), "a") as fh:
        fh.write("%d\n" % start)
    for g in range(start, gens):
        if cancelled:
            json.dump({"generation": g}, open(ckpt, "w")); sys.exit(3)
        print(json.dumps({"event": "progress", "generation": g + 1, "generations": gens, "best_eta": 7.9 + 1.0 / (g + 1),
                          "best_E": 0.1 / (g + 1), "elapsed": g * sleep, "remaining_s": (gens - g) * sleep}), flush=True)
        time.sleep(sleep)
    json.dump({"viscosity": {"value": 7.9, "interval": [7.5, 8.3]}}, open(os.path.join(out, "result.json"), "w"))
    write_png(os.path.join(out, "convergence.png"))
    print(json.dumps({"event": "done"}), flush=True); sys.exit(0)
for f in range(frames):
    if cancelled:
        open(os.path.join(out, "state.json"), "w").write(json.dumps({"frame": f}))
        sys.exit(3)
    if mode == "crash" and f == 2:
        print("segmentation fault in StokesSolver", file=sys.stderr); sys.stdout.flush()
        os.kill(os.getpid(), signal.SIGSEGV)
    print("not json noise")
    print(json.dumps({"event": "progress", "frame": f + 1, "frames": frames, "step": f, "time": f / 30,
                      "elapsed": 0.1 * f, "remaining_s": 0.1 * (frames - f)}), flush=True)
    time.sleep(sleep)
print(json.dumps({"event": "done", "frames": frames}), flush=True)
'''


@pytest.fixture
def fake_engine(tmp_path, monkeypatch):
    path = tmp_path / "fake_viscoscope"
    path.write_text(FAKE_ENGINE)
    path.chmod(0o755)
    monkeypatch.setenv("FAKE_ENGINE_ADDON", ADDON_SRC)
    return str(path)


@pytest.fixture
def use_engine(addon):
    """Set the engine in the add-on preferences for one test."""
    prefs = bpy.context.preferences.addons[MODULE].preferences

    def set_path(path):
        prefs.engine_path = path
    yield set_path
    prefs.engine_path = ""


@pytest.fixture
def press_cancel(monkeypatch):
    """press_cancel(kind, when): watch every poll an engine operator makes (the pump its modal timer
    calls) and press the panel's Cancel in the first job once `when(status)` holds. Returns (seen,
    jobs): per poll (job number from 1, progress, status line), and each job started."""
    from viscoscope.operators import runner

    def watch(kind, when):
        seen, jobs = [], []
        real_pump = runner.pump

        def pump(context, job_kind):
            running = runner.ACTIVE.get(job_kind)
            if running is not None and (not jobs or jobs[-1] is not running.job):
                jobs.append(running.job)
            result = real_pump(context, job_kind)
            st = runner.status(context, kind)
            seen.append((len(jobs), st.progress, st.status))
            if len(jobs) == 1 and when(st) and not jobs[0].cancel_requested:
                assert bpy.ops.viscoscope.cancel_job(kind=kind) == {'FINISHED'}
            return result
        monkeypatch.setattr(runner, "pump", pump)
        return seen, jobs
    return watch

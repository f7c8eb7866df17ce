"""Opens the Viscoscope sidebar tab in a real Blender window and saves a screenshot.

    xvfb-run -a -s "-screen 0 1600x1000x24" blender --factory-startup --enable-event-simulate \
        --window-geometry 0 0 1600 1000 [capture.blend] --python tests/blender/screenshot_panel.py -- OUT.png

Writes OUT.png and OUT.json ({"drawn": [panel names], "registered": bool}); quits Blender when done.
Blender 3.4 has no Python API to pick a sidebar tab, so the script clicks down the sidebar's tab
strip (simulated events) until the add-on's panels report that they were drawn.
"""

import json
import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(REPO, "sample_scenes"))

argv = sys.argv[sys.argv.index("--") + 1:]
OUT = os.path.abspath(argv[0])
SIMULATE = "--simulate" in argv  # also run "Simulate with Viscoscope" through its modal operator

state = {"tries": 0, "settle": 0, "phase": "setup", "log": [], "sim": {}}


def view3d():
    window = bpy.context.window_manager.windows[0]
    areas = [a for a in window.screen.areas if a.type == 'VIEW_3D']
    area = max(areas, key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'UI')
    return window, area, region


def setup():
    import _common
    _common.enable_addon()
    _window, area, _region = view3d()
    space = area.spaces.active
    space.show_region_ui = True
    if bpy.context.scene.camera is not None:
        space.region_3d.view_perspective = 'CAMERA'


def step():
    try:
        if state["phase"] == "setup":
            setup()
            state["phase"] = "tab"
            return 0.5
        from viscoscope import ui
        window, area, region = view3d()
        if state["phase"] == "tab":
            if "VIEW3D_PT_viscoscope_reference" in ui.DRAWN:
                state["phase"] = "settle"
                return 0.5
            # Click down the tab strip at the sidebar's right edge until our panels are drawn.
            state["tries"] += 1
            offset = 10 + 6 * (state["tries"] // 3)
            if offset > min(region.height, 600):
                state["log"].append("the Viscoscope tab never became active")
                return finish(window, area)
            x = region.x + region.width - int(10 * bpy.context.preferences.system.ui_scale)
            y = region.y + region.height - offset
            kind = state["tries"] % 3
            if kind == 0:
                window.event_simulate(type='MOUSEMOVE', value='NOTHING', x=x, y=y)
            elif kind == 1:
                ui.DRAWN.clear()
                window.event_simulate(type='LEFTMOUSE', value='PRESS', x=x, y=y)
            else:
                window.event_simulate(type='LEFTMOUSE', value='RELEASE', x=x, y=y)
                region.tag_redraw()
            return 0.15
        if state["phase"] == "settle":
            state["settle"] += 1
            area.tag_redraw()
            if state["settle"] < 3:
                return 0.3
            if SIMULATE:
                state["phase"] = "simulate"
                return start_simulation(window, area)
            return finish(window, area)
        if state["phase"] == "simulate":
            return watch_simulation(window, area)
    except Exception as exc:  # report anything, then quit: a timer must not leave Blender running
        state["log"].append("%s: %s" % (type(exc).__name__, exc))
        write_report()
        bpy.ops.wm.quit_blender()
    return None


def start_simulation(window, area):
    import time
    scene = bpy.context.scene
    # Long enough to span several of the main loop's ticks on a loaded machine.
    scene.viscoscope.sim_frames = int(os.environ.get("VISCOSCOPE_SCREENSHOT_FRAMES", "90"))
    with bpy.context.temp_override(window=window, area=area):
        result = bpy.ops.viscoscope.simulate('INVOKE_DEFAULT')
    sim = state["sim"]
    sim["invoke_result"] = sorted(result)
    # Scroll the sidebar down to the Transfer panel, where the progress bar is.
    _w, _a, region = view3d()
    x, y = region.x + region.width // 2, region.y + region.height // 2
    window.event_simulate(type='MOUSEMOVE', value='NOTHING', x=x, y=y)
    for _ in range(15):
        window.event_simulate(type='WHEELDOWNMOUSE', value='PRESS', x=x, y=y)
    # Then out of the sidebar, so that no tooltip covers it in the screenshots.
    window.event_simulate(type='MOUSEMOVE', value='NOTHING', x=area.x + area.width // 4, y=area.y + area.height // 2)
    sim["t0"] = sim["last"] = time.monotonic()
    sim["max_gap"] = 0.0
    sim["progress_seen"] = []
    return 0.05


def watch_simulation(window, area):
    """Runs on Blender's main loop while the engine works: the UI must keep ticking."""
    import time
    from viscoscope.operators import runner
    sim = state["sim"]
    now = time.monotonic()
    sim["max_gap"] = max(sim["max_gap"], now - sim["last"])
    sim["last"] = now
    st = bpy.context.scene.viscoscope.simulate_job
    if runner.is_running("simulate"):
        sim["progress_seen"].append(round(st.progress, 1))
        if st.progress >= 30.0 and "running_screenshot" not in sim:
            path = os.path.splitext(OUT)[0] + "_running.png"
            with bpy.context.temp_override(window=window, area=area):
                bpy.ops.screen.screenshot(filepath=path)
            sim["running_screenshot"] = path
        if now - sim["t0"] > 240:
            state["log"].append("the simulation did not finish in 240 s")
            return finish(window, area)
        return 0.05
    sim["status"], sim["error"] = st.status, st.error
    sim["imported"] = "Viscoscope Liquid" in bpy.data.objects
    sim["progress_seen"] = sorted(set(sim["progress_seen"]))
    return finish(window, area)


def finish(window, area):
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.screen.screenshot(filepath=OUT)
    write_report()
    bpy.ops.wm.quit_blender()
    return None


def write_report():
    try:
        from viscoscope import ui
        drawn = sorted(ui.DRAWN)
    except ImportError:
        drawn = []
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    try:
        sidebar = view3d()[2].width  # pixels: what the panels wrap their messages to
    except (StopIteration, ValueError, IndexError):
        sidebar = None
    report = {"drawn": drawn, "log": state["log"], "simulation": state["sim"], "sidebar_width": sidebar,
              "registered": hasattr(bpy.types, "VIEW3D_PT_viscoscope_identify")}
    with open(os.path.splitext(OUT)[0] + ".json", "w") as fh:
        json.dump(report, fh, indent=1)


bpy.app.timers.register(step, first_interval=1.0)

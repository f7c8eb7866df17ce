"""Drives an engine job from Blender: a modal operator's timer polls the job, the panel shows its
status, Esc or the Cancel button sends SIGTERM. Nothing in the .blend changes until a job succeeds.

Operators derive from EngineOperator and implement prepare() (returns the engine arguments) and
on_success(). execute() blocks (for scripts and background mode); invoke() returns at once.
"""

import os
import time

import bpy

from .. import engine
from ..scene_export import ExportError
from ..units import UnitError

POLL_INTERVAL = 0.1


class Running:
    def __init__(self, job, kind, out_dir, on_success, scene_name):
        self.job = job
        self.kind = kind
        self.out_dir = out_dir
        self.on_success = on_success
        self.scene_name = scene_name
        self.fit = None  # a diagnosis's (fit number, number of fits)


ACTIVE = {}  # kind → Running


def status(context, kind):
    return getattr(context.scene.viscoscope, kind + "_job")


def is_running(kind):
    running = ACTIVE.get(kind)
    return running is not None and not running.job.finished


def describe_progress(event):
    """One status line from a progress event, using whichever fields it has."""
    parts = []
    if "bake" in event:  # a Mantaflow calibration
        parts.append("Bake %s/%s: viscosity_value %.4g" % (event["bake"], event.get("bakes", "?"),
                                                           float(event.get("viscosity_value", 0.0))))
        if event.get("stage") == "score":
            parts.append("scoring")
    if event.get("stage") == "diagnose" and "fit" in event:
        parts.append("Fit %s/%s: %s" % (event["fit"], event.get("fits", "?"), event.get("model", "")))
    elif "model" in event:
        parts.append(str(event["model"]))
    if "generation" in event:
        gen = "Generation %s" % event["generation"]
        if "generations" in event:
            gen += "/%s" % event["generations"]
        if event.get("fidelity") == "coarse":
            gen += " (coarse)"
        parts.append(gen)
    elif "frame" in event:
        frame = "Frame %s" % event["frame"]
        if "frames" in event:
            frame += "/%s" % event["frames"]
        parts.append(frame)
    if "best_eta" in event:
        parts.append("best η %.4g Pa·s" % float(event["best_eta"]))
    if "best_value" in event:
        parts.append("best %.4g" % float(event["best_value"]))
    if "best_E" in event:
        parts.append("best E %.4g" % float(event["best_E"]))
    if "time" in event and "best_eta" not in event:
        parts.append("t %.3g s" % float(event["time"]))
    if "remaining_s" in event:
        parts.append("%s left" % engine.format_seconds(event["remaining_s"]))
    return " · ".join(parts) or "Running…"


def start(context, kind, args, out_dir, on_success, note=""):
    if kind in ACTIVE and not ACTIVE[kind].job.finished:
        raise engine.EngineError("a %s job is already running" % kind)
    job = engine.EngineJob(args).start()
    ACTIVE[kind] = Running(job, kind, out_dir, on_success, context.scene.name)
    st = status(context, kind)
    st.running = True
    st.progress = 0.0
    st.error = ""
    st.warning = ""
    st.note = note
    st.can_resume = False
    st.status = "Starting…"
    st.out_dir = out_dir
    context.window_manager.progress_begin(0, 100)
    return job


def start_afresh(out_dir):
    """Forget the checkpoints of an earlier run in out_dir, so that a new run of a changed job starts
    over (the engine refuses another job's checkpoint) instead of failing; the rest of its files the
    new run overwrites."""
    for folder, _dirs, files in os.walk(out_dir):
        if "checkpoint.json" in files:
            os.remove(os.path.join(folder, "checkpoint.json"))


def cancel(kind):
    running = ACTIVE.get(kind)
    if running is None or running.job.finished:
        return False
    running.job.cancel()
    return True


def pump(context, kind):
    """Poll a job once: 'RUNNING', 'FINISHED', 'CANCELLED' or 'FAILED'."""
    running = ACTIVE.get(kind)
    if running is None:
        return 'FAILED'
    scene = bpy.data.scenes.get(running.scene_name) or context.scene
    st = getattr(scene.viscoscope, kind + "_job")
    job = running.job
    for event in job.poll():
        if event.get("event") == "progress":
            if event.get("stage") == "diagnose" and "fit" in event:
                running.fit = (int(event["fit"]), int(event.get("fits", 1)))
            st.progress = 100.0 * engine.progress_fraction(event, running.fit)
            st.status = describe_progress(event)
            context.window_manager.progress_update(int(st.progress))
        elif event.get("event") == "warning":
            st.warning = str(event.get("message", ""))
    if not job.finished:
        if job.cancel_requested:
            st.status = "Cancelling…"
        return 'RUNNING'
    del ACTIVE[kind]
    context.window_manager.progress_end()
    st.running = False
    rc = job.returncode
    if rc == engine.EXIT_OK:
        try:
            running.on_success(context, running.out_dir)
        except (OSError, ValueError, RuntimeError, KeyError) as exc:
            st.error = "Engine finished but its result could not be loaded: %s" % exc
            st.status = "Failed"
            return 'FAILED'
        st.progress = 100.0
        st.status = "Done"
        return 'FINISHED'
    st.status = job.message()
    if rc == engine.EXIT_CANCELLED or job.cancel_requested:
        st.can_resume = rc == engine.EXIT_CANCELLED
        st.status = "Cancelled" + ("; Resume continues" if st.can_resume else "")
        return 'CANCELLED'
    st.error = job.message()
    st.status = "Failed"
    return 'FAILED'


def _redraw(context):
    wm = context.window_manager
    for window in wm.windows:
        for area in window.screen.areas:
            if area.type in {'VIEW_3D', 'PROPERTIES'}:
                area.tag_redraw()


class EngineOperator:
    """Mixin for operators that run one engine job."""
    job_kind = ""
    _timer = None

    note = ""  # what prepare() chose for the user (shown in the panel while and after the job runs)

    def prepare(self, context):
        """Return (engine args, out_dir); raise EngineError/ExportError for bad input."""
        raise NotImplementedError

    def on_success(self, context, out_dir):
        pass

    def _start(self, context):
        try:
            args, out_dir = self.prepare(context)
            start(context, self.job_kind, args, out_dir, self.on_success, self.note)
        except (engine.EngineError, ExportError, UnitError, OSError) as exc:
            status(context, self.job_kind).error = str(exc)
            self.report({'ERROR'}, str(exc))
            return False
        return True

    def _finish(self, result):
        kind = self.job_kind
        st = status(bpy.context, kind)
        if result == 'FAILED':
            self.report({'ERROR'}, st.error or st.status)
            return {'CANCELLED'}
        if result == 'CANCELLED':
            self.report({'WARNING'}, st.status)
            return {'CANCELLED'}
        self.report({'INFO'}, "%s: %s" % (kind.capitalize(), st.status))
        return {'FINISHED'}

    def execute(self, context):
        """Blocking run: for scripts and background mode (there is no UI to keep alive)."""
        if not self._start(context):
            return {'CANCELLED'}
        result = pump(context, self.job_kind)
        while result == 'RUNNING':
            time.sleep(POLL_INTERVAL / 2)
            result = pump(context, self.job_kind)
        return self._finish(result)

    def invoke(self, context, _event):
        if context.window is None:
            return self.execute(context)
        if not self._start(context):
            return {'CANCELLED'}
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_INTERVAL, window=context.window)
        wm.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            cancel(self.job_kind)
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        result = pump(context, self.job_kind)
        _redraw(context)
        if result == 'RUNNING':
            return {'PASS_THROUGH'}
        context.window_manager.event_timer_remove(self._timer)
        return self._finish(result)

    def cancel(self, context):
        """Blender is closing the operator (e.g. file load): stop the engine."""
        cancel(self.job_kind)
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)


class VISCOSCOPE_OT_cancel_job(bpy.types.Operator):
    """Stop the running engine job; it saves its state so Resume can continue"""
    bl_idname = "viscoscope.cancel_job"
    bl_label = "Cancel"
    bl_options = {'INTERNAL'}

    kind: bpy.props.EnumProperty(items=[('identify', "Identify", ""), ('diagnose', "Diagnose", ""),
                                        ('simulate', "Simulate", ""), ('extract', "Extract", ""),
                                        ('calibrate', "Calibrate", "")])

    def execute(self, context):
        if not cancel(self.kind):
            self.report({'WARNING'}, "No %s job is running" % self.kind)
            return {'CANCELLED'}
        status(context, self.kind).status = "Cancelling…"
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_cancel_job,)

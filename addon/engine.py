"""Runs the native ``viscoscope`` engine out of process.

This module never imports ``bpy``: a job is a subprocess whose JSON progress lines are read by a
thread into a queue, and the caller (a modal operator's timer in Blender, or a test) polls that
queue. Cancelling sends SIGTERM; the engine saves its state and exits with code 3.

Exit codes (DESIGN.md): 0 ok, 2 bad input (one-line reason on stderr), 3 cancelled, 1 internal error.
"""

import atexit
import functools
import json
import os
import queue
import shutil
import signal
import subprocess
import threading
import time

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2
EXIT_CANCELLED = 3

ENGINE_ENV = "VISCOSCOPE_ENGINE"
ENGINE_NAME = "viscoscope.exe" if os.name == "nt" else "viscoscope"


class EngineError(Exception):
    """A one-line, user-facing error about the engine or its input."""


def _is_executable(path):
    return bool(path) and os.path.isfile(path) and os.access(path, os.X_OK)


def _make_executable(path):
    try:
        os.chmod(path, os.stat(path).st_mode | 0o111)
    except OSError:
        pass


def engine_candidates(preference_path="", addon_dir=None, environ=None):
    """The places searched for the engine, in order, as (origin, path) pairs."""
    environ = os.environ if environ is None else environ
    addon_dir = os.path.realpath(addon_dir or os.path.dirname(os.path.abspath(__file__)))
    out = []
    if preference_path:
        out.append(("preferences", os.path.abspath(os.path.expanduser(preference_path))))
    if environ.get(ENGINE_ENV):
        out.append((ENGINE_ENV, os.path.abspath(os.path.expanduser(environ[ENGINE_ENV]))))
    out.append(("bundled", os.path.join(addon_dir, "bin", ENGINE_NAME)))
    out.append(("in-tree", os.path.join(os.path.dirname(addon_dir), "build", "bin", ENGINE_NAME)))
    return out


def find_engine(preference_path="", addon_dir=None, environ=None):
    """Path of the engine executable, or raise EngineError saying where it looked.

    An explicitly set location (preferences or VISCOSCOPE_ENGINE) that is not an executable is an
    error rather than silently falling back to another engine.
    """
    for origin, path in engine_candidates(preference_path, addon_dir, environ):
        if origin == "bundled" and os.path.isfile(path) and not os.access(path, os.X_OK):
            _make_executable(path)  # zip installs drop the executable bit
        if _is_executable(path):
            return path
        if origin in ("preferences", ENGINE_ENV):
            raise EngineError("Viscoscope engine from %s is not an executable file: %s" % (origin, path))
    on_path = shutil.which(ENGINE_NAME)
    if on_path:
        return on_path
    raise EngineError("Viscoscope engine not found: set it in the add-on preferences or %s" % ENGINE_ENV)


def describe_exit(returncode, stderr_text):
    """One-line message for a finished engine process."""
    reason = ""
    for line in reversed((stderr_text or "").strip().splitlines()):
        if line.strip():
            reason = line.strip()
            break
    if returncode == EXIT_OK:
        return "Finished"
    if returncode == EXIT_CANCELLED:
        return "Cancelled; state saved, run again to resume"
    if returncode == EXIT_BAD_INPUT:
        return "Bad input: " + (reason or "the engine rejected its input")
    if returncode is not None and returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = "signal %d" % -returncode
        return "Engine crashed (%s)%s" % (name, (": " + reason) if reason else "")
    return "Engine error (exit %s)%s" % (returncode, (": " + reason) if reason else "")


class EngineJob:
    """One engine subprocess with non-blocking progress.

    ``poll()`` returns the JSON events received since the last call; ``finished`` and
    ``returncode`` tell when the process is over (after its output has been drained).
    """

    def __init__(self, args, cwd=None, env=None):
        self.args = [str(a) for a in args]
        self.cwd = cwd
        self.env = env
        self.process = None
        self.events = queue.Queue()
        self.last_progress = None
        self.noise = []  # stdout lines that were not JSON
        self._stderr_lines = []
        self._threads = []
        self.cancel_requested = False
        self.started_at = None

    def start(self):
        try:
            self.process = subprocess.Popen(
                self.args, cwd=self.cwd, env=self.env,
                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                text=True, encoding="utf-8", errors="replace", bufsize=1,
                start_new_session=(os.name != "nt"))
        except OSError as exc:
            raise EngineError("Cannot start the engine %s: %s" % (self.args[0], exc.strerror or exc)) from exc
        self.started_at = time.monotonic()
        _running_jobs.add(self)
        for target, stream in ((self._read_stdout, self.process.stdout), (self._read_stderr, self.process.stderr)):
            thread = threading.Thread(target=target, args=(stream,), daemon=True)
            thread.start()
            self._threads.append(thread)
        return self

    def _read_stdout(self, stream):
        for line in stream:
            line = line.strip()
            if not line:
                continue
            try:
                event = json.loads(line)
            except ValueError:
                self.noise.append(line)
                continue
            if isinstance(event, dict):
                self.events.put(event)
            else:
                self.noise.append(line)
        stream.close()

    def _read_stderr(self, stream):
        for line in stream:
            self._stderr_lines.append(line.rstrip("\n"))
            del self._stderr_lines[:-200]
        stream.close()

    def poll(self):
        """Events received since the last call (never blocks)."""
        out = []
        while True:
            try:
                event = self.events.get_nowait()
            except queue.Empty:
                break
            if event.get("event") == "progress":
                self.last_progress = event
            out.append(event)
        return out

    @property
    def finished(self):
        if self.process is None or self.process.poll() is None:
            return False
        if any(t.is_alive() for t in self._threads):
            return False
        _running_jobs.discard(self)
        return True

    @property
    def returncode(self):
        return None if self.process is None else self.process.poll()

    @property
    def stderr(self):
        return "\n".join(self._stderr_lines)

    def message(self):
        return describe_exit(self.returncode, self.stderr)

    def cancel(self):
        """Ask the engine to stop (SIGTERM); it saves its state and exits 3."""
        self.cancel_requested = True
        if self.process is not None and self.process.poll() is None:
            try:
                self.process.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass

    def kill(self):
        if self.process is not None and self.process.poll() is None:
            self.process.kill()

    def wait(self, timeout=None):
        """Block until finished (for tests and scripts, never from the UI)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self.finished:
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError("engine did not finish within %s s" % timeout)
            time.sleep(0.02)
        return self.returncode


_running_jobs = set()


def terminate_all(grace=2.0):
    """Stop every running job (when the add-on is disabled or Blender quits)."""
    jobs = list(_running_jobs)
    for job in jobs:
        job.cancel()
    deadline = time.monotonic() + grace
    for job in jobs:
        while job.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        job.kill()
    _running_jobs.clear()


@functools.lru_cache(maxsize=32)
def _help_text(exe, mtime, words):
    try:
        proc = subprocess.run([exe, *words, "--help"], stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return proc.stdout


def help_text(exe, *words):
    """The engine's --help for a sub-command (cached per executable version on disk)."""
    try:
        mtime = os.stat(exe).st_mtime_ns
    except OSError:
        return ""
    return _help_text(exe, mtime, tuple(words))


def has_subcommand(exe, *words):
    """True when every word is a sub-command the engine lists (CLI11's "Subcommands:" section)."""
    for i, word in enumerate(words):
        text = help_text(exe, *words[:i])
        listed = text.split("Subcommands:", 1)[1].split() if "Subcommands:" in text else []
        if word not in listed:
            return False
    return True


def engine_version(exe):
    """The engine's version string ("" when it cannot tell); cached per executable on disk."""
    try:
        mtime = os.stat(exe).st_mtime_ns
    except OSError:
        return ""
    return _engine_version(exe, mtime)


@functools.lru_cache(maxsize=8)
def _engine_version(exe, _mtime):
    try:
        out = run_quick([exe, "--version"], timeout=10).strip()
    except EngineError:
        return ""
    return out.split()[-1] if out else ""


def _threads(exe, subcommand, threads):
    """--threads N when asked for and the engine accepts it (older builds do not)."""
    if threads and "--threads" in help_text(exe, subcommand):
        return ["--threads", str(threads)]
    return []


# A job outlives nothing: the engine runs in its own session, so stop it when Blender exits.
atexit.register(terminate_all)


def simulate_args(engine, scene_path, out_dir, threads=0):
    return [engine, "simulate", scene_path, "--out", out_dir, "--progress", "json"] + \
        _threads(engine, "simulate", threads)


def identify_args(engine, job_path, out_dir, threads=0):
    return [engine, "identify", job_path, "--out", out_dir, "--progress", "json"] + \
        _threads(engine, "identify", threads)


def diagnose_args(engine, job_path, out_dir, threads=0, time_budget_s=0.0, effects=None):
    """`time_budget_s` for the whole diagnosis (0: each fit has the job's own); `effects` the
    candidates by name (None: every one the scene can hold)."""
    args = [engine, "diagnose", job_path, "--out", out_dir, "--progress", "json", "--time-budget", "%g" % time_budget_s]
    if effects is not None:
        args += ["--effects", ",".join(effects)]
    return args + _threads(engine, "diagnose", threads)


# A job's "extraction" names (observe.h, parseExtractionOptions) → `extract`'s options, so that the
# Preview's masks are drawn from the same settings as Identify's.
EXTRACT_OPTIONS = {
    "first": "--first", "last": "--last", "step": "--step", "fps": "--fps",
    "background_frames": "--background-frames", "clean_plate": "--clean-plate",
    "clean_plate_frame": "--clean-plate-frame", "exclude_mask": "--exclude", "weights": "--weights",
    "mog2_variance_threshold": "--var-threshold", "mog2_minimum_variance": "--min-variance",
    "mog2_shadow_threshold": "--shadow-threshold", "threshold": "--threshold", "edge_coverage": "--edge-coverage",
    "close_kernel_px": "--close", "open_kernel_px": "--open", "min_blob_px": "--min-blob",
}


def extract_args(engine, video, out_dir, extraction=None):
    """`extract` with a job's "extraction" settings (the engine's names) as command-line options."""
    args = [engine, "extract", video, "--out", out_dir, "--progress", "json"]
    for key, value in (extraction or {}).items():
        if key == "compensate_gain":
            args += [] if value else ["--no-gain-compensation"]
        elif key in EXTRACT_OPTIONS:
            args += [EXTRACT_OPTIONS[key], str(value)]
        else:
            raise EngineError("extraction setting %r has no `extract` option" % key)
    return args


def run_quick(args, timeout=60.0):
    """Run a short engine command (sub-second: camera conversion, PnP) and return its stdout.

    Raises EngineError with the engine's one-line reason when it fails.
    """
    try:
        proc = subprocess.run([str(a) for a in args], stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout)
    except OSError as exc:
        raise EngineError("Cannot start the engine %s: %s" % (args[0], exc.strerror or exc)) from exc
    except subprocess.TimeoutExpired as exc:
        raise EngineError("Engine command timed out after %.0f s: %s" % (timeout, " ".join(map(str, args[1:3])))) from exc
    if proc.returncode != EXIT_OK:
        raise EngineError(describe_exit(proc.returncode, proc.stderr))
    return proc.stdout


def apparent_viscosity(exe, scene_path, shear_rate):
    """The viscosity (Pa·s) of the material in scene_path at shear_rate (1/s), by the engine's law."""
    out = run_quick([exe, "viscosity", scene_path, "--shear-rate", repr(float(shear_rate))])
    try:
        return float(json.loads(out)["viscosity_pa_s"])
    except (ValueError, KeyError, TypeError) as exc:
        raise EngineError("the engine's viscosity answer is not understood: %r" % out[:200]) from exc


def format_seconds(seconds):
    if seconds is None:
        return "?"
    try:
        seconds = float(seconds)
    except (TypeError, ValueError):
        return "?"
    if seconds != seconds or seconds < 0:
        return "?"
    seconds = int(round(seconds))
    if seconds >= 3600:
        return "%dh%02dm" % (seconds // 3600, (seconds % 3600) // 60)
    if seconds >= 60:
        return "%dm%02ds" % (seconds // 60, seconds % 60)
    return "%ds" % seconds


def progress_fraction(event, fit=None):
    """Fraction done in [0, 1] from a progress event (frame/frames or generation/generations); within
    a diagnosis, `fit` is (this fit's number from 1, the number of fits) and each fit is a share."""
    if fit is not None:
        number, count = fit
        return min(max((number - 1 + progress_fraction(event)) / count, 0.0), 1.0) if count > 0 else 0.0
    if not event:
        return 0.0
    if "bake" in event and "bakes" in event:  # a calibration: each bake an equal share, frames within it
        try:
            bake, bakes = float(event["bake"]), float(event["bakes"])
        except (TypeError, ValueError):
            return 0.0
        inner = progress_fraction({k: v for k, v in event.items() if k not in ("bake", "bakes")})
        return min(max((bake - 1 + inner) / bakes, 0.0), 1.0) if bakes > 0 else 0.0
    for num, den in (("frame", "frames"), ("generation", "generations")):
        try:
            n, d = float(event[num]), float(event[den])
        except (KeyError, TypeError, ValueError):
            continue
        if d > 0:
            return min(max(n / d, 0.0), 1.0)
    return 0.0

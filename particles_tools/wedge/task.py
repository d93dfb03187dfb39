"""One variant on a worker: ``particles run`` itself (``cli.main``, in this process) on the
variant's config file into the variant's folder, with its figures and a thumbnail of the chosen
frame sent back.

Runs inside a Dask worker process, which imports Taichi and the engine once. Each variant gets a
fresh Taichi program (``particles run`` initialises it, ``runtime.reset`` ends it: ~0.25 s): the
offline kernel cache only pays off that way: a kernel's cache key includes the ids of the field
trees it touches, which keep growing while a program lives, so the second scene of a program
misses the entries the first scene of any ``particles run`` left and compiles everything again
(~5 s of a sparks variant against 0.1 s). The reset also writes what the variant did compile to
the cache (a Dask worker ends with os._exit, so Taichi's own write at exit never runs) and frees
the scene's fields.

A variant always runs with ``--resume`` semantics: if a worker was killed mid-variant, the rerun
elsewhere keeps the whole frames the dead one left (frames are renamed into place when whole) and
renders the rest, byte for byte as one uninterrupted run. Every failure becomes an exit code and a
message in the result; nothing here raises into Dask, so one bad variant never stops the others.
"""
from __future__ import annotations

import contextlib
import io
import os
import platform
import re
import tempfile
import threading
import time

#: events on this topic carry frame progress to the submitting client
TOPIC = "particles-wedge"
_one_at_a_time = threading.Lock()  # one Taichi program per process: variants never overlap in it
_EVENT_EVERY = 0.2  # seconds between frame events per variant


class _FrameWatch:
    """Counts the whole frames in the variant's folder a few times a second (a frame appears
    under its name only when whole) and sends the count to the client as a Dask event."""

    def __init__(self, variant_id: str, folder: str, emit):
        self.id, self.folder, self.emit = variant_id, folder, emit
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wedge-frames", daemon=True)
        self._sent = -1

    def count(self) -> int:
        try:
            return sum(1 for f in os.listdir(self.folder) if f.startswith("frame_"))
        except OSError:
            return 0

    def _send(self):
        n = self.count()
        if n != self._sent:
            self._sent = n
            self.emit({"variant": self.id, "frame": n})

    def _run(self):
        while not self._stop.wait(_EVENT_EVERY):
            self._send()

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self._send()
        return False


def _dask_events(run: str):
    """Send an event tagged with this wedge's ``run`` token (a cluster may serve several)."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not on a Dask worker (a direct call): no events
        return lambda msg: None
    return lambda msg: worker.log_event(TOPIC, dict(msg, run=run))


def _compile_seconds() -> float:
    """Taichi's running total of compile time (kernels loaded from the offline cache add ~0);
    0 when no program is live (the run stopped before starting one)."""
    from taichi.lang import impl

    prog = impl.get_runtime().prog
    return prog.get_total_compilation_time() if prog is not None else 0.0


def thumbnail_png(path: str, width: int) -> bytes:
    """The PNG at ``path`` scaled to ``width`` pixels wide (never enlarged), as PNG bytes."""
    from PIL import Image

    with Image.open(path) as im:
        im = im.convert("RGB")
        if im.width > width:
            im = im.resize((width, max(1, round(im.height * width / im.width))), Image.LANCZOS)
        buf = io.BytesIO()
        im.save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def render_variant(task: dict) -> dict:
    """Render one variant; ``task`` is plain data (see ``command._task``: the variant's id and
    config text, its folder, arch, threads, the chosen frame). Returns the result:
    ``variant``, ``status`` (``ok`` / ``failed``), ``exit_code``, ``message``, ``wall_s``,
    ``frames``, ``peak_particles``, ``dropped``, ``resumed_at``, ``worker``, ``thumbnail`` (PNG
    bytes or None), and the worker-side figures for the overhead: clock (``t_start``, ``t_end``),
    ``init_s`` (Taichi's import, init and reset), ``compile_s`` (kernels compiled, not
    loaded from the offline cache), ``process_cpu_s`` (this process's CPU so far)."""
    with _one_at_a_time:
        t_start = time.time()
        out = {"variant": task["id"], "status": "failed", "exit_code": 1, "message": "",
               "wall_s": 0.0, "frames": 0, "peak_particles": "", "dropped": "", "resumed_at": 0,
               "worker": f"{platform.node()}:{os.getpid()}", "thumbnail": None,
               "t_start": t_start, "init_s": 0.0, "compile_s": 0.0}
        try:
            _render(task, out)
        except Exception as e:  # a bug, not the user's input: still one line, and the others go on
            out.update(exit_code=1, message=f"internal error: {e.__class__.__name__}: "
                       + " ".join(str(e).split())[:300])
        out["t_end"] = time.time()
        out["process_cpu_s"] = time.process_time()  # this worker's CPU so far, start-up included
        return out


def _render(task: dict, out: dict) -> None:
    t0 = time.perf_counter()  # the first variant of a process imports Taichi and the engine
    from engine import runtime
    from engine.render.resume import whole_frames
    from .. import cli

    out["init_s"] = time.perf_counter() - t0
    fd, path = tempfile.mkstemp(prefix=f"wedge-{task['id']}-", suffix=".toml")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(task["config_text"])
        argv = ["--arch", task["arch"]] + (["--threads", str(task["threads"])] if task["threads"]
                                           else [])
        argv += ["run", path, "--out", task["out"], "--resume", "--quiet"]
        stdout, stderr = io.StringIO(), io.StringIO()
        try:
            with _FrameWatch(task["id"], task["out"], _dask_events(task.get("run"))), \
                    contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                code = cli.main(argv)  # particles run, as the command line runs it
            out["compile_s"] = _compile_seconds()  # this variant's program: its compile time
        finally:
            t1 = time.perf_counter()
            runtime.reset()  # writes the kernels compiled here to the offline cache, frees fields
            out["init_s"] += time.perf_counter() - t1
    finally:
        os.remove(path)
    out.update(_summary_figures(stdout.getvalue()), exit_code=code,
               status="ok" if code == 0 else "failed", frames=whole_frames(task["out"]))
    if code != 0:
        errors = [line.removeprefix("error: ") for line in stderr.getvalue().splitlines()
                  if line.startswith("error: ")]
        out["message"] = " ".join(" ".join(errors).split())[:500]
    out["thumbnail"] = _chosen_thumbnail(task, out["frames"])


_PEAK = re.compile(r"peak live particles ([\d,]+) of [\d,]+; dropped ([\d,]+)")
_WALL = re.compile(r"; ([\d.]+) s wall")
_RESUMED = re.compile(r"\(resumed at frame (\d+)\)")


def _summary_figures(text: str) -> dict:
    """Peak particles, dropped, wall seconds and the resume frame from ``particles run``'s
    summary line (blank where the run printed none: a failure, a scene without particles)."""
    got = {}
    m = _PEAK.search(text)
    if m:
        got["peak_particles"], got["dropped"] = (int(g.replace(",", "")) for g in m.groups())
    m = _WALL.search(text)
    if m:
        got["wall_s"] = float(m.group(1))
    m = _RESUMED.search(text)
    got["resumed_at"] = int(m.group(1)) if m else 0
    return got


def _chosen_thumbnail(task, whole: int):
    """The chosen frame (``sheet_frame``, default the last), or the last whole frame a failed
    variant left; None when there is none."""
    from engine.render.output import frame_path

    if whole < 1:
        return None
    k = task["sheet_frame"]
    k = whole - 1 if k is None or k >= whole else k
    try:
        return thumbnail_png(frame_path(task["out"], k), task["thumb_width"])
    except OSError:
        return None

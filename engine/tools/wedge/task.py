"""One variant on a worker: ``particles run``'s own path (``commands.cmd_run``) into the variant's
folder, with its figures and a thumbnail of the chosen frame sent back.

Runs inside a Dask worker process, which imports Taichi and the engine once. Each variant gets a
fresh Taichi program (``runtime.init`` before, ``runtime.reset`` after: ~0.25 s), because the
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
import threading
import time

#: events on this topic carry frame progress to the submitting client
TOPIC = "particles-wedge"
_one_at_a_time = threading.Lock()  # one Taichi program per process: variants never overlap in it
_EVENT_EVERY = 0.2  # seconds between frame events per variant


class _FrameEvents:
    """``cmd_run``'s progress: frame counts to the client as Dask events, a few per second."""

    def __init__(self, variant_id: str, total: int, emit):
        self.id, self.total, self.emit = variant_id, total, emit
        self._last = 0.0

    def update(self, frame: int, alive: int) -> None:
        now = time.monotonic()
        if now - self._last >= _EVENT_EVERY or frame >= self.total:
            self._last = now
            self.emit({"variant": self.id, "frame": frame})

    def done(self) -> None:
        pass


def _dask_events(run: str):
    """Send an event tagged with this wedge's ``run`` token (a cluster may serve several)."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not on a Dask worker (a direct call): no events
        return lambda msg: None
    return lambda msg: worker.log_event(TOPIC, dict(msg, run=run))


def _compile_seconds() -> float:
    """Taichi's running total of compile time (kernels loaded from the offline cache add ~0)."""
    from taichi.lang import impl

    return impl.get_runtime().prog.get_total_compilation_time()


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
    """Render one variant; ``task`` is plain data (see ``command._task``). Returns the result:
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
    t0 = time.perf_counter()  # the first variant of a process also imports Taichi and the engine
    from ... import runtime

    runtime.init(task["arch"], threads=task["threads"])  # a fresh program for each variant
    out["init_s"] = time.perf_counter() - t0
    try:
        _render_in_program(task, out)
    finally:
        t0 = time.perf_counter()
        runtime.reset()  # writes the kernels compiled here to the offline cache, frees the fields
        out["init_s"] += time.perf_counter() - t0


def _render_in_program(task: dict, out: dict) -> None:
    from ...config import ConfigError
    from ..commands import cmd_run
    from ..errors import UserError
    from .spec import Variant, file_sha256, variant_config

    if file_sha256(task["config"]) != task["config_sha256"]:
        out.update(exit_code=2, message=f"config: {task['config']} changed since the wedge started "
                                        f"(or is another file on this worker)")
        return
    variant = Variant(task["id"], tuple(map(tuple, task["sets"])), tuple(task["texts"]), task["seed"])
    try:
        cfg = variant_config(task["config"], task["frames"], task["size"], variant)
    except (ConfigError, ValueError, UserError) as e:  # the client checked it: the file differs here
        out.update(exit_code=2, message=" ".join(str(e).split()))
        return
    report = {}
    compiled = _compile_seconds()
    try:
        events = _FrameEvents(task["id"], cfg.frame_count, _dask_events(task.get("run")))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            cmd_run(_run_args(task), cfg=cfg, progress=events, report=report)
        out.update(status="ok", exit_code=0)
    except UserError as e:  # diverged (3), output failure (4), refused folder (2)
        out.update(exit_code=e.exit_code, message=" ".join(str(e).split()))
    finally:
        out["compile_s"] = _compile_seconds() - compiled
    out.update(wall_s=round(report.get("wall", 0.0), 3), frames=report.get("whole_frames", 0),
               peak_particles=report.get("peak_alive", ""), dropped=report.get("dropped", ""),
               resumed_at=report.get("resumed_at", 0))
    out["thumbnail"] = _chosen_thumbnail(task, out["frames"])


def _run_args(task):
    import argparse

    return argparse.Namespace(config=task["config"], out=task["out"], format="png", resume=True,
                              overwrite=False, quiet=True)


def _chosen_thumbnail(task, whole: int):
    """The chosen frame (``sheet_frame``, default the last), or the last whole frame a failed
    variant left; None when there is none."""
    from ...render.output import frame_path

    if whole < 1:
        return None
    k = task["sheet_frame"]
    k = whole - 1 if k is None or k >= whole else k
    try:
        return thumbnail_png(frame_path(task["out"], k), task["thumb_width"])
    except OSError:
        return None

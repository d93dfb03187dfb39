"""One variant on a worker: ``particles run``'s own path (``commands.cmd_run``) into the variant's
folder, with its figures and a thumbnail of the chosen frame sent back.

Runs inside a Dask worker process. Taichi is initialised once per process (``runtime.init`` is a
no-op after the first call), so a worker pays the import and ``ti.init`` once and every later
variant starts with Taichi's offline cache already loaded. A variant always runs with ``--resume``
semantics: if a worker was killed mid-variant, the rerun elsewhere keeps the whole frames the dead
one left (frames are renamed into place when whole) and renders the rest, byte for byte as one
uninterrupted run. Every failure becomes an exit code and a message in the result; nothing here
raises into Dask, so one bad variant never stops the others.
"""
from __future__ import annotations

import contextlib
import io
import os
import threading
import time

#: events on this topic carry frame progress to the submitting client
TOPIC = "particles-wedge"
#: a process holding more Taichi SNode trees than this starts a fresh Taichi program before the next
#: variant (the LLVM backends allow 512 per program; a sparks scene opens about 10)
MAX_TREES = 256
#: ... or holding more memory than this fraction of the worker's memory limit (fields of earlier
#: scenes stay allocated until the program is reset)
MAX_MEMORY_FRACTION = 0.5
_one_at_a_time = threading.Lock()  # one Taichi program per process: variants never overlap in it
_EVENT_EVERY = 0.2  # seconds between frame events per variant
_process = {"variants": 0}  # variants this worker process has rendered


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


def _recycle_taichi_if_full(arch: str, threads) -> bool:
    """Start a fresh Taichi program when this one holds many SNode trees or much memory; the
    kernels of a scene are its own, so nothing warm is lost but ``ti.init`` (~0.15 s)."""
    from taichi.lang import impl

    from ... import runtime

    trees = impl.get_runtime().prog.get_snode_tree_size()
    full = trees > MAX_TREES
    if not full:
        try:
            import psutil

            from distributed import get_worker

            limit = get_worker().memory_manager.memory_limit
            full = bool(limit) and psutil.Process().memory_info().rss > MAX_MEMORY_FRACTION * limit
        except (ImportError, ValueError, AttributeError):
            pass
    if full:
        runtime.reset()
        runtime.init(arch, threads=threads)
    return full


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
    bytes or None), and the worker-side clock (``t_start``, ``t_end``, ``init_s``) for the
    overhead figures."""
    with _one_at_a_time:
        t_start = time.time()
        out = {"variant": task["id"], "status": "failed", "exit_code": 1, "message": "",
               "wall_s": 0.0, "frames": 0, "peak_particles": "", "dropped": "", "resumed_at": 0,
               "worker": f"{os.uname().nodename}:{os.getpid()}", "thumbnail": None,
               "t_start": t_start, "init_s": 0.0}
        try:
            _render(task, out)
        except Exception as e:  # a bug, not the user's input: still one line, and the others go on
            out.update(exit_code=1, message=f"internal error: {e.__class__.__name__}: "
                       + " ".join(str(e).split())[:300])
        out["t_end"] = time.time()
        return out


def _render(task: dict, out: dict) -> None:
    t0 = time.perf_counter()  # the first variant of a process also imports Taichi and the engine
    from ... import runtime
    from ...config import ConfigError
    from ..commands import cmd_run
    from ..errors import UserError
    from .spec import Variant, file_sha256, variant_config

    if _process["variants"] == 0:
        runtime.init(task["arch"], threads=task["threads"])  # once per worker process
        out["init_s"] = time.perf_counter() - t0
    else:
        _recycle_taichi_if_full(task["arch"], task["threads"])
    _process["variants"] += 1
    if file_sha256(task["config"]) != task["config_sha256"]:
        out.update(exit_code=2, message=f"config: {task['config']} changed since the wedge started "
                                        f"(or is another file on this worker)")
        return
    variant = Variant(task["id"], tuple(map(tuple, task["sets"])), tuple(task["texts"]), task["seed"])
    report = {}
    try:
        cfg = variant_config(task["config"], task["frames"], task["size"], variant)
        args = _run_args(task)
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            events = _FrameEvents(task["id"], cfg.frame_count, _dask_events(task.get("run")))
            cmd_run(args, cfg=cfg, progress=events, report=report)
        out.update(status="ok", exit_code=0)
    except UserError as e:
        out.update(exit_code=e.exit_code, message=" ".join(str(e).split()))
    except (ConfigError, ValueError) as e:  # checked by the client: only if the file differs here
        out.update(exit_code=2, message=" ".join(str(e).split()))
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

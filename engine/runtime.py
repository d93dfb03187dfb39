"""The one place that calls ``ti.init``.

Taichi allows one initialisation per process and every field and kernel belongs to it. The engine
initialises lazily on first use; a host program that already called ``ti.init`` itself (a game with
its own Taichi canvas) is detected and left alone.
"""
from __future__ import annotations

import contextlib
import io
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")  # no network check at import (PERF-NOTES)
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")  # keep stdout for our own output

import taichi as ti  # noqa: E402

ARCHES = ("cpu", "cuda", "vulkan", "metal", "gpu")

_state = {"arch": None, "kwargs": None}
_reset_hooks = []  # caches holding fields or kernels of the current Taichi program


def _host_initialised() -> bool:
    try:
        from taichi.lang import impl

        return impl.get_runtime().prog is not None
    except Exception:  # pragma: no cover - private API moved
        return False


def init(arch: str = "cpu", *, threads: int | None = None, debug: bool = False,
         kernel_profiler: bool = False) -> str:
    """Initialise Taichi once for this process and return the arch in use.

    ``arch`` is one of :data:`ARCHES`. Later calls are no-ops (a different arch after the first
    call raises, since fields already allocated cannot move). ``threads`` caps CPU threads.
    The offline cache stays on so a second run of the same scene starts fast; it lives where
    ``PARTICLES_TI_CACHE`` points (a folder) if set, else in Taichi's default place.
    ``kernel_profiler`` turns on Taichi's per-kernel timer (``particles profile`` uses it).
    """
    if arch not in ARCHES:
        raise ValueError(f"arch: unknown value {arch!r}; allowed: {', '.join(ARCHES)}")
    if _state["arch"] is not None:
        if arch != _state["arch"] and _state["arch"] != "host":
            raise RuntimeError(f"Taichi already initialised with arch={_state['arch']}, not {arch}")
        return _state["arch"]
    if _host_initialised():
        _state["arch"] = "host"
        return "host"
    kwargs = dict(arch=getattr(ti, arch), default_fp=ti.f32, offline_cache=True,
                  log_level=ti.WARN, debug=debug, random_seed=0,
                  kernel_profiler=kernel_profiler)
    if os.environ.get("PARTICLES_TI_CACHE"):
        kwargs["offline_cache_file_path"] = os.environ["PARTICLES_TI_CACHE"]
    if threads and arch == "cpu":
        kwargs["cpu_max_num_threads"] = int(threads)
    with contextlib.redirect_stdout(io.StringIO()):  # "[Taichi] Starting on arch=..." banner
        ti.init(**kwargs)
    _state["arch"] = arch
    return arch


def on_reset(hook) -> None:
    """Register a function that drops a cache of fields/kernels when the program is reset."""
    _reset_hooks.append(hook)


def reset() -> None:
    """Throw away the Taichi program (every field and kernel) and forget the init, so the next
    ``init`` starts a fresh one. The LLVM backends allow at most 512 live SNode trees and 2048
    SNodes per program, and every field allocated after a kernel ran opens a new tree: a long
    process that builds many scenes (a test session) resets between groups of scenes. Objects
    built before the reset must not be used after it."""
    for hook in _reset_hooks:
        hook()
    if _state["arch"] not in (None, "host"):
        ti.reset()
    _state["arch"] = None


class Interrupted(Exception):
    """Raised between steps when the stop check (a signal handler's flag) asks to stop."""


_stop_check = [None]


def set_stop_check(fn) -> None:
    """``fn()`` -> bool, polled between steps (``None``: never stop). The command line installs
    its signal flag here so SIGINT/SIGTERM stop a long frame mid-way, not only between frames."""
    _stop_check[0] = fn


def check_stop() -> None:
    """Raise :class:`Interrupted` if the stop check says so. Cheap: one call per step batch."""
    fn = _stop_check[0]
    if fn is not None and fn():
        raise Interrupted("stopped")


def ensure_init() -> str:
    """Initialise with defaults unless already done (by the engine or by the host)."""
    return _state["arch"] or init("cpu")

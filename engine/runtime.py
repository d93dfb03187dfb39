"""The one place that calls ``ti.init``.

Taichi allows one initialisation per process and every field and kernel belongs to it. The engine
initialises lazily on first use; a host program that already called ``ti.init`` itself (a game with
its own Taichi canvas) is detected and left alone.
"""
from __future__ import annotations

import atexit
import contextlib
import io
import os
import threading

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")  # no network check at import (PERF-NOTES)
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")  # keep stdout for our own output

import taichi as ti  # noqa: E402

from . import affinity, front_end  # noqa: E402  (front_end installed at import: see engine.front_end)

ARCHES = ("cpu", "cuda", "vulkan", "metal", "gpu", "auto")
# "gpu" takes the first of these that starts; "auto" the same, else the CPU. (Taichi's own ti.gpu
# list also probes OpenGL, which crashed the process on a headless machine without a GPU.)
_GPU_ORDER = ("cuda", "vulkan", "metal")

_state = {"arch": None, "requested": None, "kwargs": None, "thread": None, "pinned": {}}
_reset_hooks = [front_end.KEPT_TEXTS.forget_folder]  # caches of the current Taichi program (fields,
# kernels; the kept texts' cache folder, which the next program may keep elsewhere)


class ArchUnavailable(RuntimeError):
    """The requested backend cannot start on this machine (no device, no driver)."""


class WrongThread(RuntimeError):
    """An engine call from a thread other than the one that initialised Taichi."""


def check_thread(where: str) -> None:
    """The thread policy: Taichi is single-threaded (a kernel compiled or launched from a second
    thread gives "nested kernels" errors, silently wrong state or an abort in Taichi's runtime),
    so every engine call must come from the thread that initialised Taichi (the engine's
    :func:`init`, or the thread that first built a scene in a host that initialised Taichi
    itself). Any other thread gets one line naming the method, and nothing happens."""
    owner = _state["thread"]
    if owner is not None and owner[0] != threading.get_ident():
        raise WrongThread(f"{where}: called from thread {threading.current_thread().name!r}, but Taichi "
                          f"was initialised on thread {owner[1]!r}: the engine is single-threaded; call it "
                          f"from that thread (hand work to it with a queue)")


def _own_thread() -> None:
    t = threading.current_thread()
    _state["thread"] = (threading.get_ident(), t.name)


def _host_initialised() -> bool:
    try:
        from taichi.lang import impl

        return impl.get_runtime().prog is not None
    except Exception:  # pragma: no cover - private API moved
        return False


def _arch_in_use() -> str:
    """The backend Taichi really started: "cpu" for x64/arm64, else Taichi's arch name."""
    from taichi.lang import impl

    arch = impl.current_cfg().arch
    return "cpu" if arch in (ti.x64, ti.arm64) else arch.name


def pinned() -> dict:
    """{thread id: CPU} of the CPU pool's workers this program pinned (engine.affinity)."""
    return dict(_state["pinned"])


def one_thread(count: int, limit: int) -> bool:
    """Whether a loop over ``count`` items (at most ``limit``) runs on the launching thread: a
    compile-time choice a kernel takes as a template flag, true on the CPU backend only. There each
    parallel loop is a task handed to Taichi's thread pool, whose workers sleep on a condition
    variable: waking them and being told they are done costs 20–170 µs on this 2-core machine,
    whatever the loop's size (ten empty parallel loops 390–700 µs a launch, ten serial ones 15 µs),
    more than a small loop's work. A GPU keeps every loop parallel: one thread there is one of
    thousands."""
    return count <= limit and _arch_in_use() == "cpu"


def init(arch: str = "cpu", *, threads: int | None = None, debug: bool = False,
         log_level: str = "warn", kernel_profiler: bool = False) -> str:
    """Initialise Taichi once for this process and return the arch really in use ("cpu",
    "cuda", "vulkan", "metal").

    ``arch`` is one of :data:`ARCHES`. A named backend that cannot start raises
    :class:`ArchUnavailable` (Taichi would otherwise fall back to the CPU silently); only "auto"
    falls back, and the return value says what ran. Later calls are no-ops (a different arch
    after the first call raises, since fields already allocated cannot move). ``threads`` caps
    CPU threads. ``log_level`` ("warn", "error") is Taichi's; the command line keeps Taichi's
    warnings (offline-cache lock contention between processes) off its one-line errors with
    "error". The offline cache stays on so a second run of the same scene starts fast; it
    lives where ``PARTICLES_TI_CACHE`` points (a folder) if set, else in Taichi's default place.
    ``kernel_profiler`` turns on Taichi's per-kernel timer (``particles profile`` uses it).
    On the CPU, Taichi's worker threads are then held one to a core (engine.affinity;
    ``PARTICLES_PIN_THREADS=0``: not): :func:`pinned` says which.
    """
    if arch not in ARCHES:
        raise ValueError(f"arch: unknown value {arch!r}; allowed: {', '.join(ARCHES)}")
    if _state["arch"] is not None:
        check_thread("engine.runtime.init")
        if arch not in ("auto", _state["requested"], _state["arch"]) and _state["arch"] != "host":
            raise RuntimeError(f"Taichi already initialised with arch={_state['arch']}, not {arch}")
        return _state["arch"]
    if _host_initialised():
        _state["arch"] = _state["requested"] = "host"
        _own_thread()
        return "host"
    level = {"warn": ti.WARN, "error": ti.ERROR}[log_level]
    # cfg_optimization off: Taichi's own CFG passes (store-to-load forwarding over a reaching-
    # definitions analysis, dead-store elimination over live variables) are superlinear in a
    # task's size and were ~2/3 of compiling the large step kernels (crates' located step_fixed:
    # 92 -> 37 s cold, its first frame 112 -> 48 s; 40-frame cold runs of nine configs 1.3-2.4x faster); LLVM's
    # mem2reg, GVN and DSE do that work after it, so frame times stay within this machine's noise
    # (README's figures, 2026-11-26). Frames are deterministic either way; the switch moves the
    # last bits of some scenes (hair and crates the same for their first frames, water within
    # 3e-5 m after two; chaotic scenes grow that). Autodiff's adjoints need the passes:
    # cfg_optimized() below.
    kwargs = dict(default_fp=ti.f32, offline_cache=True, log_level=level, debug=debug,
                  random_seed=0, kernel_profiler=kernel_profiler, cfg_optimization=False)
    if os.environ.get("PARTICLES_TI_CACHE"):
        kwargs["offline_cache_file_path"] = os.environ["PARTICLES_TI_CACHE"]
    if threads and arch in ("cpu", "auto"):
        kwargs["cpu_max_num_threads"] = int(threads)
    threads_before = affinity.threads_now()
    with contextlib.redirect_stdout(io.StringIO()):  # "[Taichi] Starting on arch=..." banner
        if arch == "cpu":
            ti.init(arch=ti.cpu, **kwargs)
        else:
            wanted = [getattr(ti, a) for a in (_GPU_ORDER if arch in ("gpu", "auto") else (arch,))]
            try:  # ERROR level: probing a missing driver warns "libcuda.so lib not found"
                ti.init(arch=wanted, enable_fallback=False, **dict(kwargs, log_level=ti.ERROR))
                ti.set_logging_level(level)
            except RuntimeError:
                if arch != "auto":
                    raise ArchUnavailable(
                        f"{arch} cannot start on this machine (no {arch if arch != 'gpu' else 'GPU'} "
                        f"device or driver found)") from None
                ti.init(arch=ti.cpu, **kwargs)
    _state["arch"], _state["requested"] = _arch_in_use(), arch
    _own_thread()
    front_end.install()
    # Taichi's CPU workers one to a core (engine.affinity: they took turns on one)
    _state["pinned"] = affinity.pin_workers(threads_before) if _state["arch"] == "cpu" else {}
    if not _state.get("exit_hook"):
        atexit.register(_write_cache_at_exit)
        _state["exit_hook"] = True
    return _state["arch"]


def _write_cache_at_exit() -> None:
    """Taichi writes the kernels it compiled into its offline cache when its program is torn
    down. At interpreter exit that teardown may never run (a scene's kernels and fields still
    referenced as the interpreter finalises): every ``particles run`` then started cold, 11.6 s
    instead of ~3. So the program this module started is torn down explicitly at exit, on the
    thread that owns it (another thread's exit leaves it alone)."""
    front_end.KEPT_TEXTS.save()
    owner = _state["thread"]
    if _state["arch"] in (None, "host") or owner is None or owner[0] != threading.get_ident():
        return
    try:
        reset()
    except Exception:  # pragma: no cover - nothing to report to at exit
        pass


@contextlib.contextmanager
def cfg_optimized():
    """Taichi's CFG passes on for the kernels compiled inside (``init`` turns them off): reverse-
    mode autodiff needs them — an adjoint compiled without them came out wrong (a harmonic well's
    gradient off by 115 N/kg, tests/test_potential.py). Wrap every ``kernel.grad()`` call: the
    switch is read when a kernel compiles, so a compiled one pays only two attribute writes."""
    cfg = ti.lang.impl.current_cfg()
    before = cfg.cfg_optimization
    cfg.cfg_optimization = True
    try:
        yield
    finally:
        cfg.cfg_optimization = before


@contextlib.contextmanager
def without_kernel_cse():
    """Taichi's whole-kernel common-subexpression pass off for the kernels compiled inside (its
    ``opt_level`` 0; ``init`` keeps 1). The pass compares statements pairwise over a task, so it
    grows with the square of a task's size: it was 97 of the 108 s that the rigid step with
    coupled joints (the lantern's one-launch ``whole``, engine.rigid.kernel) took to compile cold
    (Taichi's scoped profiler, 2026-11-28). LLVM's GVN and EarlyCSE merge the same expressions
    afterwards. A kernel must always compile under the same setting (it is part of the cache
    key), so a kernel that uses this is compiled inside it every time (engine.launch's
    ``lean``). Only the largest kernels use it: the XPBD step and the particle steps that meet
    boxes or capsules (README "Compile time"). It changes how their last bits round (crates' and
    debris' frames differ from before it; lantern's do not); each stays deterministic."""
    cfg = ti.lang.impl.current_cfg()
    before = cfg.opt_level
    cfg.opt_level = 0
    try:
        yield
    finally:
        cfg.opt_level = before


def on_reset(hook) -> None:
    """Register a function that drops a cache of fields/kernels when the program is reset."""
    _reset_hooks.append(hook)


def reset() -> None:
    """Throw away the Taichi program (every field and kernel) and forget the init, so the next
    ``init`` starts a fresh one. The LLVM backends allow at most 512 live SNode trees and 2048
    SNodes per program, and every field allocated after a kernel ran opens a new tree: a long
    process that builds many scenes (a test session) resets between groups of scenes. Objects
    built before the reset must not be used after it (they say so in one line)."""
    check_thread("engine.runtime.reset")
    for hook in _reset_hooks:
        hook()
    if _state["arch"] not in (None, "host"):
        ti.reset()
    _state["arch"] = _state["requested"] = _state["thread"] = None
    _state["pinned"] = {}


class Interrupted(Exception):
    """Raised between steps when the stop check (a signal handler's flag) asks to stop."""


_stop_check = [None]


def set_stop_check(fn):
    """``fn()`` -> bool, polled between steps (``None``: never stop). The command line installs
    its signal flag here so SIGINT/SIGTERM stop a long frame mid-way, not only between frames.
    Returns the check it replaces (to put back afterwards)."""
    old, _stop_check[0] = _stop_check[0], fn
    return old


def check_stop() -> None:
    """Raise :class:`Interrupted` if the stop check says so. Cheap: one call per step batch."""
    fn = _stop_check[0]
    if fn is not None and fn():
        raise Interrupted("stopped")


def ensure_init(where: str = "engine") -> str:
    """Initialise with defaults unless already done (by the engine or by the host); from another
    thread than the one that did, :class:`WrongThread` naming ``where``."""
    if _state["arch"]:
        check_thread(where)
        return _state["arch"]
    return init("cpu")

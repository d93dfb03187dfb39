"""The game API's load costs and its argument checks, measured in one process.

* first build of campfire (a config this process has not built: every kernel specialised for its
  fields) beside a level restart (``from_file`` of a config built and discarded before, first
  step, first render: the discarded scene is reused, engine.reuse) — target <= 0.3 s;
* a second copy alive at once, prepared on a loading screen (``ParticleScene.prepare``);
* resident memory over ten build/discard cycles of one level — target <= 20 MB in all;
* ``add_emitter`` of an effect the scene already compiled (spare rows and slots) — target <= 50 ms;
* a render size never drawn before (ndarray targets: allocation, no engine kernel compiles) —
  target <= 50 ms;
* the argument checks: ``step()`` + ``render()`` through the API against the same calls on the
  Scene underneath (no checks), alternating blocks of frames, median block each — target within 2%;
* why fields are reused rather than rebuilt: a small kernel's first call on a new field
  (``ti.template()``: a compile) against its first call on a new ndarray (none).
"""
from __future__ import annotations

import os
import statistics
import time

import numpy as np

from .. import CONFIGS
from .common import Row, sync
from .kernels import scale_field, scale_ndarray

DT = 1.0 / 60.0


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _level(path, size, **kw):
    """from_file + first step + first render: (scene, seconds)."""
    from engine.api import ParticleScene

    t0 = time.perf_counter()
    s = ParticleScene.from_file(path, **kw) if isinstance(path, str) else ParticleScene(path, **kw)
    s.step(DT)
    s.render(*size)
    sync()
    return s, time.perf_counter() - t0


def _first_call(kernel, make, repeats=3):
    """Median seconds of ``kernel``'s first call on a newly made array."""
    times = []
    for _ in range(repeats):
        x = make()
        t0 = time.perf_counter()
        kernel(x, 1.0)
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _overhead(scene, size, frames, blocks):
    """Median ms per frame of API step + render, and of the Scene's own calls (no checks)."""
    out = np.empty((size[1], size[0], 4), np.uint8)
    raw = scene.scene

    def api():
        scene.step(DT)
        scene.render(*size, out=out)

    def direct():
        raw.advance(DT)
        raw.render(*size, out=out)

    med = {api: [], direct: []}
    for b in range(blocks):
        for fn in ((api, direct) if b % 2 == 0 else (direct, api)):
            t0 = time.perf_counter()
            for _ in range(frames):
                fn()
            sync()
            med[fn].append((time.perf_counter() - t0) / frames * 1e3)
    return statistics.median(med[api]), statistics.median(med[direct])


class _NoWork:
    """A Scene with its work taken out (stepping and drawing): an API call on it costs only its
    argument checks and dispatch."""

    def __init__(self, real):
        self._real = real

    def __getattr__(self, key):
        return getattr(self._real, key)

    def advance(self, dt):
        pass

    def save_positions(self):
        pass

    def render(self, *args, **kw):
        return None


def _checks_us(scene, size, calls):
    """µs per frame of ``step()`` + ``render()`` through the API when the work underneath is
    taken out: the cost of the checks."""
    out = np.empty((size[1], size[0], 4), np.uint8)
    real, scene.scene = scene.scene, _NoWork(scene.scene)
    try:
        t0 = time.perf_counter()
        for _ in range(calls):
            scene.step(DT)
            scene.render(*size, out=out)
        return (time.perf_counter() - t0) / calls * 1e6
    finally:
        scene.scene = real


def run(quick: bool = False):
    import taichi as ti

    from engine.api import ParticleScene

    name = "sparks" if quick else "campfire"
    path = os.path.join(CONFIGS, f"{name}.toml")
    size = (320, 180) if quick else (640, 360)
    sec = f"api: loads without hitches ({name}, {size[0]}x{size[1]})"
    rows = []
    from engine.config import read_toml

    data = read_toml(path)
    data["name"], data["seed"] = name, 9_999_999  # a config this process has not built yet
    s, first = _level(data, size)
    s.close()
    restarts = []
    for _ in range(3 if quick else 5):
        s, t = _level(data, size)
        restarts.append(t)
        s.close()
    restart = statistics.median(restarts)
    rows.append(Row(sec, f"first build of {name}", first, "s", "from_file + first step + render, kernels compiled "
                    "(offline cache warm)"))
    rows.append(Row(sec, "level restart", restart, "s", f"target <= 0.3 s; the discarded scene reused; median of "
                    f"{len(restarts)}; x{first / restart:.0f} faster than the first build"))
    a, _ = _level(data, size)
    t0 = time.perf_counter()
    ParticleScene.prepare(data, copies=1, sizes=[size])
    prep = time.perf_counter() - t0
    b, second = _level(data, size)
    rows.append(Row(sec, "second copy, prepared", second, "s",
                    f"alive beside the first; prepare(copies=1) took {prep:.1f} s on the loading screen"))
    a.close(), b.close()
    cycles = 3 if quick else 10
    m0 = rss_mb()
    for _ in range(cycles):
        s, _ = _level(data, size)
        for _ in range(5):
            s.step(DT)
        s.close()
    grow = rss_mb() - m0
    rows.append(Row(sec, f"{cycles} build/discard cycles", max(grow, 1e-3), "MB", f"resident memory growth "
                    f"(target <= 20 MB); {m0:.1f} -> {m0 + grow:.1f} MB"))
    s, _ = _level(data, size)
    s.warm_up([size])
    for _ in range(30):
        s.step(DT)
    t0 = time.perf_counter()
    s.add_emitter({"name": "bench_sparks", "effect": "sparks", "rate": 300.0, "position": [0.5, 0.2, 0.0]})
    s.step(DT)
    s.render(*size)
    sync()
    add = (time.perf_counter() - t0) * 1e3
    rows.append(Row(sec, "add_emitter, effect compiled", add, "ms",
                    f"target <= 50 ms; add + first step + render; {'in place' if s.last_add is None else s.last_add}"))
    new_sizes = [(size[0] + 8 * k, size[1] + 8 * k) for k in range(1, 4)]
    firsts, agains = [], []
    for w, h in new_sizes:
        t0 = time.perf_counter()
        s.render(w, h)
        sync()
        t1 = time.perf_counter()
        s.render(w, h)
        sync()
        firsts.append(t1 - t0)
        agains.append(time.perf_counter() - t1)
    rows.append(Row(sec, "a new render size", statistics.median(firsts) * 1e3, "ms",
                    f"target <= 50 ms; first render at {new_sizes[0][0]}x{new_sizes[0][1]}+ (same size again "
                    f"{statistics.median(agains) * 1e3:.1f} ms)"))
    with_checks, without = _overhead(s, size, 10 if quick else 20, 6 if quick else 10)
    us = _checks_us(s, size, 200 if quick else 5000)
    rows.append(Row(sec, "argument checks per frame", us, "us",
                    f"step() + render() with the work underneath taken out: {us / 10 / without:.3f}% of a "
                    f"{without:.1f} ms frame (target within 2%)", {"checks_share": us / 1e3 / without}))
    rows.append(Row(sec, "step + render, checked", with_checks, "ms/frame",
                    f"{100 * (with_checks / without - 1):+.1f}% vs the Scene's own calls, alternating blocks "
                    f"(the machine's noise: the checks alone are the row above)"))
    rows.append(Row(sec, "step + render, unchecked", without, "ms/frame", "Scene.advance + Scene.render"))
    s.close()
    n = 1 << 16
    field_first = _first_call(scale_field, lambda: ti.field(ti.f32, shape=n))
    nd_first = _first_call(scale_ndarray, lambda: ti.ndarray(ti.f32, shape=n))
    rows.append(Row(sec, "first call, new field (template)", field_first * 1e3, "ms",
                    "a small kernel specialised for each new field: a compile"))
    rows.append(Row(sec, "first call, new ndarray", nd_first * 1e3, "ms",
                    f"compiled once for every ndarray of its type: x{field_first / nd_first:.0f} cheaper"))
    return rows

"""Every shipped effect config as a game would run it: ``ParticleScene.from_file``, then per frame
``step(1/60)`` + ``render(1280, 720)`` into a reused array; no file output.

Each scene is first simulated (without drawing) to the middle of its run, so pools are as full as
the effect gets, then a few frames are drawn to warm up, then frames are timed. The empty-scene row
is the fixed cost of a frame (background kept, clear, resolve, read-back) with nothing to draw.
Beside each config: the splat's cost per covered pixel-sprite pair against a plain loop
(``splatcost``) and the composite alone (``composite_ms``), on the CPU's tile schedule.
"""
from __future__ import annotations

import glob
import inspect
import os
import time

from .. import CONFIGS
from .common import Row, sync

W, H = 1280, 720
DT = 1.0 / 60.0


def _render_fn(scene, w, h):
    """``render(w, h)``, into one reused array where the API offers ``out=``."""
    import numpy as np

    if "out" in inspect.signature(scene.render).parameters:
        out = np.empty((h, w, 4), np.uint8)
        return lambda: scene.render(w, h, out=out)
    return lambda: scene.render(w, h)


def time_frames(scene, w, h, frames, warm_seconds, warm_frames=5):
    """Median ms of (step + render), of step alone and of render alone, per frame."""
    render = _render_fn(scene, w, h)
    for _ in range(round(warm_seconds / DT)):
        scene.step(DT)
    for _ in range(warm_frames):
        scene.step(DT)
        render()
    sync()
    both, steps, draws = [], [], []
    for _ in range(frames):
        t0 = time.perf_counter()
        scene.step(DT)
        sync()
        t1 = time.perf_counter()
        render()
        sync()
        t2 = time.perf_counter()
        both.append(t2 - t0)
        steps.append(t1 - t0)
        draws.append(t2 - t1)
    med = lambda v: sorted(v)[len(v) // 2]  # noqa: E731
    return med(both) * 1e3, med(steps) * 1e3, med(draws) * 1e3


def splat_cost(scene, w, h):
    """(covered pairs, splat ms, plain-loop ms) of the scene's last frame (None: no sprites or
    not the CPU's tile schedule): ``splatcost``."""
    from . import splatcost

    inner = scene.scene
    R = getattr(inner, "renderer", None)
    if R is None or not getattr(R, "has_particles", False) or R.schedule != "tiles" or not R.last_pairs:
        return None
    t = R.targets(w, h)
    dep = t.fdep if R.mesh is not None else t.depth
    return splatcost.measure(R, t, dep)


def composite_ms(scene, w, h, rounds: int = 7):
    """Best-of-``rounds`` ms of the composite alone (the CPU's ``composite_tiles``: the reduced
    layer's upsample, the full level's resolve, tone map and pack) on the arguments of one more
    frame drawn at the scene's state; None where the renderer is not the CPU's tile schedule."""
    R = getattr(scene.scene, "renderer", None)
    if R is None or R.schedule != "tiles":
        return None
    kernels, calls = R._k, []
    kernel = kernels["composite_tiles"]
    R._k = dict(kernels, composite_tiles=lambda *a: (calls.append(a), kernel(*a))[1])
    try:
        _render_fn(scene, w, h)()
    finally:
        R._k = kernels  # (the kernels' dict is shared by every renderer: left as it was)
    best = 1e9
    for _ in range(rounds):
        sync()
        t0 = time.perf_counter()
        for a in calls:
            kernel(*a)
        sync()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def empty_frame_ms(w, h, frames):
    from engine.api import ParticleScene

    # a scene needs an emitter: one that never emits (driven from code) leaves nothing to draw
    scene = ParticleScene.from_dict({"name": "empty", "fps": 60, "frames": 1,
                                     "render": {"width": w, "height": h},
                                     "emitters": [{"rate": 10.0, "emitting": False}]})
    _, _, draw = time_frames(scene, w, h, frames, 0.0)
    return draw


def run(quick: bool = False, configs=None):
    from engine.api import ParticleScene

    w, h = (320, 180) if quick else (W, H)
    frames = 5 if quick else 40
    paths = configs or sorted(glob.glob(os.path.join(CONFIGS, "*.toml")))
    if quick:
        paths = [p for p in paths if os.path.basename(p) == "sparks.toml"]
    sec = f"effects at {w}x{h}: step(1/60) + render, as a game runs them"
    rows = []
    worst = None
    for path in paths:
        name = os.path.basename(path)[:-5]
        t0 = time.perf_counter()
        scene = ParticleScene.from_file(path)
        build = time.perf_counter() - t0
        cfg = scene.cfg
        warm = 0.2 if quick else min(2.0, 0.5 * cfg.frame_count / cfg.fps)
        total, step, draw = time_frames(scene, w, h, frames, warm)
        live = scene.live_count()
        fps = 1e3 / total
        rows.append(Row(sec, name, fps, "frames/s",
                        f"{total:6.2f} ms = step {step:5.2f} + render {draw:6.2f}; live {live:,}; "
                        f"build {build:.1f} s", {"ms": total, "step_ms": step, "render_ms": draw}))
        cost = splat_cost(scene, w, h)
        if cost is not None:
            n, t_splat, t_ref = cost
            rows.append(Row(sec, f"  splat, {name}", t_splat / max(n, 1) * 1e6, "ns/pair",
                            f"{n:,} covered pixel-sprite pairs, {t_splat:.2f} ms; plain loop over "
                            f"them {t_ref / max(n, 1) * 1e6:.2f} ns/pair: x{t_splat / max(t_ref, 1e-9):.1f} "
                            f"(target <= 3)", {"pairs": n, "splat_ms": t_splat, "ref_ms": t_ref}))
        comp = composite_ms(scene, w, h)
        if comp is not None:
            rows.append(Row(sec, f"  composite, {name}", comp, "ms",
                            "alone, best of 7, on one more frame's arguments (target <= 3 ms at 1280x720)"))
        worst = fps if worst is None else min(worst, fps)
        del scene
    if worst is not None:
        rows.append(Row(sec, "worst effect", worst, "frames/s", "target 60, floor 30"))
    empty = empty_frame_ms(w, h, frames)
    rows.append(Row(sec, "empty scene, render only", empty, "ms/frame",
                    "fixed cost of a frame (target <= 3 ms at 1280x720)"))
    return rows

"""Offline throughput: does writing frames slow a render down? The same config, simulated and
rendered at 1280×720, measured three ways side by side (each on a freshly built scene, timing the
frame loop only, not the build; the three take turns, twice, and each keeps its best round, so
a burst of load on this shared machine does not land on one of them only):

* sim + render: ``advance_frame()`` + ``render()``, images dropped: the rate to match;
* ``particles run``: the command's own frame loop (commands.render_frames) writing PNGs through
  the encoder threads (one per core, at least two);
* the same with one encoder thread (how ``particles run`` wrote before).

Target (issue 12): ``particles run`` at least 80% of sim + render.
"""
from __future__ import annotations

import os
import tempfile
import time

from .. import CONFIGS
from .common import Row

CONFIG = os.path.join(CONFIGS, "campfire.toml")


def _scene(size, frames):
    from ...config import load_config
    from ...scene import Scene

    cfg = load_config(CONFIG, {"render.width": size[0], "render.height": size[1]})
    return Scene(cfg), cfg


def _sim_render(size, frames, warm) -> float:
    scene, _ = _scene(size, frames)
    for _ in range(warm):
        scene.advance_frame()
        scene.render()
    t0 = time.perf_counter()
    for _ in range(frames):
        scene.advance_frame()
        scene.render()
    return frames / (time.perf_counter() - t0)


def _run(size, frames, warm, workers, out) -> float:
    from ...render.output import FrameWriter, prepare_dir
    from ..commands import render_frames

    scene, cfg = _scene(size, frames)
    for _ in range(warm):  # the same warm-up, not written
        scene.advance_frame()
        scene.render()
    prepare_dir(out, overwrite=False)
    writer = FrameWriter(out, "png", cfg.fps, cfg.name, workers=workers)
    t0 = time.perf_counter()
    failure, out_failure = render_frames(scene, writer, 0, frames)
    if failure or out_failure:
        raise RuntimeError(f"render failed: {failure or out_failure}")
    return frames / (time.perf_counter() - t0)


def run(quick: bool = False):
    from ...render.output import default_workers

    size = (320, 180) if quick else (1280, 720)
    frames, warm, rounds = (6, 2, 1) if quick else (45, 30, 2)
    workers = default_workers()
    sec = (f"output: {os.path.basename(CONFIG)} at {size[0]}x{size[1]}, {frames} frames after "
           f"{warm} warm-up frames, PNG, best of {rounds}")
    base = many = one = 0.0
    with tempfile.TemporaryDirectory(prefix="particles-bench-out-") as tmp:
        for r in range(rounds):
            base = max(base, _sim_render(size, frames, warm))
            many = max(many, _run(size, frames, warm, workers, os.path.join(tmp, f"many{r}")))
            one = max(one, _run(size, frames, warm, 1, os.path.join(tmp, f"one{r}")))
    return [
        Row(sec, "sim + render (no output)", base, "frames/s"),
        Row(sec, f"particles run, {workers} encoders", many, "frames/s",
            f"{100 * many / base:.0f}% of sim + render (target >= 80%)", extra={"ratio": many / base}),
        Row(sec, "particles run, 1 encoder", one, "frames/s",
            f"{100 * one / base:.0f}% of sim + render", extra={"ratio": one / base}),
    ]

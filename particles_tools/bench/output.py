"""Offline throughput: does writing frames slow a render down? One scene (a shipped config at
1280×720), after a warm-up, runs blocks of frames three ways in turn:

* sim + render: ``advance_frame()`` + ``render()``, images dropped: the rate to match;
* ``particles run``: the command's own frame loop (commands.render_frames) writing PNGs through
  its encoder threads (one per core, at least two), the writer drained at the block's end;
* the same with one encoder thread (how ``particles run`` wrote before).

Blocks alternate (A B C A B C ...) and each way reports its median block, so the load of a shared
machine drifting during the run lands on all three alike. Target (issue 12): ``particles run`` at
least 80% of sim + render.
"""
from __future__ import annotations

import os
import statistics
import tempfile
import time

from .. import CONFIGS
from .common import Row

CONFIG = os.path.join(CONFIGS, "campfire.toml")


def run(quick: bool = False):
    from engine.config import load_config
    from engine.render.output import FrameWriter, default_workers, prepare_dir
    from engine.scene import Scene
    from ..commands import render_frames

    size = (320, 180) if quick else (1280, 720)
    block, rounds, warm = (2, 1, 2) if quick else (8, 4, 30)
    workers = default_workers()
    cfg = load_config(CONFIG, {"render.width": size[0], "render.height": size[1]})
    scene = Scene(cfg)
    for _ in range(warm):
        scene.advance_frame()
        scene.render()
    rates = {"plain": [], "many": [], "one": []}
    with tempfile.TemporaryDirectory(prefix="particles-bench-out-") as tmp:
        for r in range(rounds):
            t0 = time.perf_counter()
            for _ in range(block):
                scene.advance_frame()
                scene.render()
            rates["plain"].append(block / (time.perf_counter() - t0))
            for key, n in (("many", workers), ("one", 1)):
                out = os.path.join(tmp, f"{key}{r}")
                prepare_dir(out, overwrite=False)
                writer = FrameWriter(out, "png", cfg.fps, cfg.name, workers=n)
                t0 = time.perf_counter()
                failure, out_failure = render_frames(scene, writer, 0, block)
                if failure or out_failure:
                    raise RuntimeError(f"render failed: {failure or out_failure}")
                rates[key].append(block / (time.perf_counter() - t0))
    base, many, one = (statistics.median(rates[k]) for k in ("plain", "many", "one"))
    sec = (f"output: {os.path.basename(CONFIG)} at {size[0]}x{size[1]} after {warm} frames, "
           f"{rounds} rounds of {block}-frame blocks, median block")
    return [
        Row(sec, "sim + render (no output)", base, "frames/s"),
        Row(sec, f"particles run, {workers} encoders", many, "frames/s",
            f"{100 * many / base:.0f}% of sim + render (target >= 80%)", extra={"ratio": many / base}),
        Row(sec, "particles run, 1 encoder", one, "frames/s",
            f"{100 * one / base:.0f}% of sim + render", extra={"ratio": one / base}),
    ]

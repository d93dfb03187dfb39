"""``particles profile CONFIG``: where a frame's time goes, per kernel (Taichi's kernel profiler).

Runs the config as a game would (``step(1/60)`` + ``render(W, H)`` into a reused array), first
simulating to the middle of its run, then times ``frames`` frames and prints, per kernel, the
milliseconds it takes per frame and its launches per frame, beside the wall time per frame.
The process must have been initialised with ``runtime.init(..., kernel_profiler=True)``.
"""
from __future__ import annotations

import re
import time


def _kernel_table():
    """{kernel name: (launches, total ms)} since the last clear (Taichi 1.7's profiler records)."""
    from taichi.lang import impl

    prog = impl.get_runtime().prog
    prog.sync_kernel_profiler()
    prog.update_kernel_profiler()
    out = {}
    for rec in prog.get_kernel_profiler_records():
        # a record per offloaded task: "<kernel>_c<id>_<n>_kernel_<k>_<kind>"; sum a kernel's tasks
        m = re.match(r"^(.*?)_c\d+_\d+_kernel_(\d+)", rec.name)
        name, task = (m.group(1), int(m.group(2))) if m else (rec.name, 0)
        n, ms = out.get(name, (0, 0.0))
        out[name] = (n + (task == 0), ms + rec.kernel_time)
    return out


def profile(path: str, width: int = 1280, height: int = 720, frames: int = 20, warm_seconds=None,
            scene=None):
    """Returns the report as text (``scene``: the config at ``path`` built already)."""
    import numpy as np
    import taichi as ti

    from engine.api import ParticleScene

    if scene is None:
        scene = ParticleScene.from_file(path)
    cfg = scene.cfg
    dt = 1.0 / 60.0
    warm = min(2.0, 0.5 * cfg.frame_count / cfg.fps) if warm_seconds is None else warm_seconds
    for _ in range(round(warm / dt)):
        scene.step(dt)
    out = np.empty((height, width, 4), np.uint8)
    for _ in range(3):
        scene.step(dt)
        scene.render(width, height, out=out)
    ti.sync()
    ti.profiler.clear_kernel_profiler_info()
    t0 = time.perf_counter()
    for _ in range(frames):
        scene.step(dt)
        scene.render(width, height, out=out)
    ti.sync()
    wall = (time.perf_counter() - t0) / frames * 1e3
    table = sorted(_kernel_table().items(), key=lambda kv: -kv[1][1])
    total = sum(ms for _, (_, ms) in table) / frames
    lines = [f"# {path} at {width}x{height}, {frames} frames: {wall:.2f} ms per frame wall, "
             f"{total:.2f} ms in kernels",
             f"  {'kernel':<44} {'ms/frame':>9} {'launches/frame':>15}"]
    for name, (n, ms) in table:
        lines.append(f"  {name[:44]:<44} {ms / frames:9.3f} {n / frames:15.1f}")
    return "\n".join(lines)

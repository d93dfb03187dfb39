"""Shared pieces of the benchmark: one table row, timing by median of repeats, formatting."""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field


@dataclass
class Row:
    """One line of the bench table: ``section`` groups rows, ``name`` says what was measured,
    ``value`` in ``unit``, and ``notes`` holds ratios measured side by side (text)."""

    section: str
    name: str
    value: float
    unit: str
    notes: str = ""
    extra: dict = field(default_factory=dict)  # machine-readable figures (ratios, counts)

    @property
    def finite_positive(self) -> bool:
        return math.isfinite(self.value) and self.value > 0


def sync():
    import taichi as ti

    ti.sync()


def time_median(fn, repeats: int, warmup: int = 1, taichi: bool = True) -> float:
    """Median wall seconds of ``fn()`` over ``repeats`` runs after ``warmup`` runs (Taichi synced
    after each unless ``taichi`` is False): :func:`time_interleaved` of one callable."""
    return time_interleaved({"fn": fn}, repeats, warmup, taichi)["fn"]


def time_interleaved(fns: dict, repeats: int, warmup: int = 2, taichi: bool = True) -> dict:
    """Median wall seconds of each ``fns[name]()`` (Taichi synced after each unless ``taichi`` is
    False), the callables taken in turn — warm-up rounds, then ``repeats`` timed rounds of one
    call each — so each sees the machine in the same state: measured one after another, the first
    kernel of a section was slower for its first calls (a state that is not the code's) and the
    ratios between them moved."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    if taichi:
        sync()
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            if taichi:
                sync()
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(t) for name, t in times.items()}


def frame_seconds(scene, frames: int) -> float:
    """Mean wall seconds of ``frames`` frames of ``scene`` stepped and rendered (after one frame
    rendered outside the timing: the renderer's first call compiles)."""
    scene.render()
    t0 = time.perf_counter()
    for _ in range(frames):
        scene.advance_frame()
        scene.render()
    return (time.perf_counter() - t0) / frames


def format_table(rows) -> str:
    lines = []
    section = None
    w = max([len(r.name) for r in rows] + [10])
    for r in rows:
        if r.section != section:
            section = r.section
            lines.append(f"\n== {section} ==")
        lines.append(f"  {r.name:<{w}}  {_fmt(r.value):>10} {r.unit:<12} {r.notes}")
    return "\n".join(lines).lstrip("\n")


def _fmt(v: float) -> str:
    if not math.isfinite(v):
        return str(v)
    if abs(v) >= 100:
        return f"{v:,.0f}"
    if abs(v) >= 1:
        return f"{v:.2f}"
    return f"{v:.3g}"

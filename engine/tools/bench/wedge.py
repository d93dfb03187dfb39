"""``particles wedge`` against the same variants rendered by ``particles run`` one after another.

The variants are seeds of configs/sparks.toml (``--seeds N``; the k-th one is ``particles run
--seed <config seed + k>``), so both sides render exactly the same frames — the bench checks the
bytes. Every figure is the wall time of whole commands as subprocesses (interpreter start, Taichi
import and init, kernel compilation, simulation, PNG writing). The wedge's overhead per variant is
the worker time not spent inside a variant, ``(workers × wall − Σ variant time) / variants``:
cluster start, Taichi's import and init in each worker, scheduling gaps, idle tails, index and
contact-sheet writes.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

from .. import CONFIGS, ROOT
from .common import Row

CONFIG = os.path.join(CONFIGS, "sparks.toml")
SECTION = "wedge: {n} variants x {frames} frames of configs/sparks.toml at {size}, subprocesses"


def _particles(*argv) -> float:
    env = dict(os.environ, TI_SKIP_VERSION_CHECK="ON",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "engine", *map(str, argv)], env=env, cwd=ROOT,
                       capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"particles {argv[0]} failed ({p.returncode}): {p.stderr.strip()[-500:]}")
    return wall


def _same_frames(a: str, b: str) -> bool:
    names = sorted(f for f in os.listdir(a) if f.startswith("frame_"))
    if names != sorted(f for f in os.listdir(b) if f.startswith("frame_")):
        return False
    for name in names:
        with open(os.path.join(a, name), "rb") as fa, open(os.path.join(b, name), "rb") as fb:
            if fa.read() != fb.read():
                return False
    return bool(names)


def _wedge(tmp, tag, n, frames, size, workers, threads):
    out = os.path.join(tmp, f"wedge-{tag}")
    wall = _particles("wedge", CONFIG, "--seeds", n, "--frames", frames, "--size", size,
                      "--workers", workers, "--threads", threads, "--out", out, "--quiet")
    with open(os.path.join(out, "wedge.json")) as fh:
        timing = json.load(fh)["timing"]
    overhead = (workers * wall - timing["busy_s"]) / n
    return out, wall, overhead, timing


def run(quick: bool = False):
    from ...config import read_toml

    n, frames, size = (2, 3, "160x90") if quick else (12, 60, "640x360")
    seed0 = read_toml(CONFIG).get("seed", 0)
    section = SECTION.format(n=n, frames=frames, size=size)
    rows = []
    with tempfile.TemporaryDirectory(prefix="particles-bench-wedge-") as tmp:
        seq_dirs = [os.path.join(tmp, "seq", f"v{k:03d}") for k in range(n)]
        t0 = time.perf_counter()
        for k, d in enumerate(seq_dirs):
            _particles("run", CONFIG, "--seed", seed0 + k, "--frames", frames, "--size", size,
                       "--out", d, "--quiet")
        seq = time.perf_counter() - t0
        rows.append(Row(section, f"{n} x particles run, one after another", seq, "s",
                        f"{seq / n:.2f} s per variant (process start, Taichi init, kernels, frames)"))
        setups = [("2 workers x 1 thread", 2, 1)] + ([] if quick else [
            ("2 workers x 2 threads", 2, 2), ("1 worker x 2 threads", 1, 2)])
        for tag, workers, threads in setups:
            out, wall, overhead, t = _wedge(tmp, f"{workers}w{threads}t", n, frames, size, workers,
                                            threads)
            same = all(_same_frames(os.path.join(out, f"v{k:03d}"), d) for k, d in enumerate(seq_dirs))
            target = "; target <= 0.6" if (workers, threads) == (2, 1) else ""
            rows.append(Row(section, f"particles wedge, {tag}", wall, "s",
                            f"x{wall / seq:.2f} of one after another{target}; overhead "
                            f"{overhead:.2f} s per variant (target < 0.3): cluster start "
                            f"{t['start_s']:.2f} s, Taichi import+init {t['taichi_init_s_mean']:.2f} s "
                            f"per worker, gap {1000 * t['gap_s_mean']:.0f} ms, index write "
                            f"{1000 * t['write_s_mean']:.1f} ms, sheet {1000 * t['sheet_s']:.0f} ms; "
                            f"{t['busy_s'] / n:.2f} s inside each variant; same bytes as run: "
                            f"{'yes' if same else 'NO'}",
                            extra={"ratio": wall / seq, "overhead_s": overhead, "same": same}))
    return rows

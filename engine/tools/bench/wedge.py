"""``particles wedge`` against the same variants rendered by ``particles run`` one after another.

The variants are seeds of configs/sparks.toml (``--seeds N``; the k-th one is ``particles run
--seed <config seed + k>``), so both sides render exactly the same frames — the bench checks the
bytes. Every figure is the wall time of whole commands as subprocesses (interpreter start, Taichi
import and init, kernel compilation, simulation, PNG writing), the two sides interleaved and the
best of two kept (one pass with ``quick``). The wedge's overhead per variant is the worker time
spent outside variants, less the idle tail while the last variant finishes elsewhere:
``(workers × wall − Σ variant time − tail) / variants`` — interpreter and cluster start, Taichi's
import and init in each worker, scheduling gaps, the contact sheet.
"""
from __future__ import annotations

import json
import math
import os
import shutil
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
    shutil.rmtree(out, ignore_errors=True)
    wall = _particles("wedge", CONFIG, "--seeds", n, "--frames", frames, "--size", size,
                      "--workers", workers, "--threads", threads, "--out", out, "--quiet")
    with open(os.path.join(out, "wedge.json")) as fh:
        t = json.load(fh)["timing"]
    t["overhead_s"] = (workers * wall - t["busy_s"] - t["tail_idle_s"]) / n
    return out, wall, t


def _sequential(seq_dirs, seed0, frames, size) -> float:
    t0 = time.perf_counter()
    for k, d in enumerate(seq_dirs):
        _particles("run", CONFIG, "--seed", seed0 + k, "--frames", frames, "--size", size,
                   "--out", d, "--overwrite", "--quiet")
    return time.perf_counter() - t0


def run(quick: bool = False):
    """Sequential runs and each wedge set-up, interleaved ``repeats`` times (best of each): the
    machines are shared, and a load that drifts between the two sides would decide the ratio."""
    from ...config import read_toml

    n, frames, size, repeats = (2, 3, "160x90", 1) if quick else (12, 60, "640x360", 2)
    seed0 = read_toml(CONFIG).get("seed", 0)
    section = SECTION.format(n=n, frames=frames, size=size)
    setups = [("2 workers x 1 thread", 2, 1)] + ([] if quick else [("2 workers x 2 threads", 2, 2)])
    seq = math.inf
    best = {}
    with tempfile.TemporaryDirectory(prefix="particles-bench-wedge-") as tmp:
        seq_dirs = [os.path.join(tmp, "seq", f"v{k:03d}") for k in range(n)]
        for _ in range(repeats):
            seq = min(seq, _sequential(seq_dirs, seed0, frames, size))
            for tag, workers, threads in setups:
                out, wall, t = _wedge(tmp, f"{workers}w{threads}t", n, frames, size, workers, threads)
                t["same"] = all(_same_frames(os.path.join(out, f"v{k:03d}"), d)
                                for k, d in enumerate(seq_dirs))
                if tag not in best or wall < best[tag][0]:
                    best[tag] = (wall, t)
    rows = [Row(section, f"{n} x particles run, one after another", seq, "s",
                f"{seq / n:.2f} s per variant (process start, Taichi init, kernels, frames); "
                f"best of {repeats}")]
    for tag, workers, _ in setups:
        wall, t = best[tag]
        target = "; target <= 0.6" if workers == 2 and t["threads_per_worker"] == 1 else ""
        rows.append(Row(section, f"particles wedge, {tag}", wall, "s",
                        f"x{wall / seq:.2f} of one after another{target}; overhead "
                        f"{t['overhead_s']:.2f} s per variant (target < 0.3): cluster start "
                        f"{t['start_s']:.2f} s, Taichi import+init {t['taichi_init_s_mean']:.2f} s per "
                        f"worker, gap {1000 * t['gap_s_mean']:.0f} ms, sheet {1000 * t['sheet_s']:.0f} "
                        f"ms; idle tail {t['tail_idle_s']:.1f} s; {t['busy_s'] / n:.2f} s inside each "
                        f"variant; same bytes as run: {'yes' if t['same'] else 'NO'}",
                        extra={"ratio": wall / seq, "overhead_s": t["overhead_s"], "same": t["same"]}))
    return rows

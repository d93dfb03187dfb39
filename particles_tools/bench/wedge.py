"""``particles wedge`` against the same variants rendered by ``particles run`` one after another.

The variants are seeds of configs/sparks.toml (``--seeds N``; the k-th one is ``particles run
--seed <config seed + k>``), so both sides render exactly the same frames — the bench checks the
bytes. Every figure is the wall time of whole commands as subprocesses (interpreter start, Taichi
import and init, kernel compilation, simulation, PNG writing), the two sides interleaved and the
best of two kept (one pass with ``quick``). CPU seconds (of the runs; of the wedge's workers and
client, as the wedge counts them) show the work each side does, whatever else a shared machine
runs. The wedge's overhead per variant is the worker time spent outside variants, less the idle
tail while the last variant finishes elsewhere: ``(workers × wall − Σ variant time − tail) /
variants`` — interpreter and cluster start, Taichi's imports in each worker and its program start
and reset around each variant, scheduling gaps, the contact sheet.
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


def _cpu_children() -> float:
    """CPU seconds (user + system) of the finished child processes and their descendants (NaN
    where the platform cannot say)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return math.nan
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _particles(*argv):
    """Run ``particles ARGV``; (wall seconds, CPU seconds of it and its worker processes)."""
    env = dict(os.environ, TI_SKIP_VERSION_CHECK="ON",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    c0, t0 = _cpu_children(), time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "engine", *map(str, argv)], env=env, cwd=ROOT,
                       capture_output=True, text=True, timeout=3600)
    wall, cpu = time.perf_counter() - t0, _cpu_children() - c0
    if p.returncode != 0:
        raise RuntimeError(f"particles {argv[0]} failed ({p.returncode}): {p.stderr.strip()[-500:]}")
    return wall, cpu


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
    wall, _ = _particles("wedge", CONFIG, "--seeds", n, "--frames", frames, "--size", size,
                           "--workers", workers, "--threads", threads, "--out", out, "--quiet")
    with open(os.path.join(out, "wedge.json")) as fh:
        t = json.load(fh)["timing"]
    t["overhead_s"] = (workers * wall - t["busy_s"] - t["tail_idle_s"]) / n
    return out, wall, t  # CPU: the wedge's own count (its workers are not this process's children)


def _sequential(seq_dirs, seed0, frames, size):
    """The runs one after another: (wall seconds, CPU seconds)."""
    runs = [_particles("run", CONFIG, "--seed", seed0 + k, "--frames", frames, "--size", size,
                       "--out", d, "--overwrite", "--quiet") for k, d in enumerate(seq_dirs)]
    return sum(w for w, _ in runs), sum(c for _, c in runs)


def run(quick: bool = False):
    """Sequential runs and each wedge set-up, interleaved ``repeats`` times (best of each): the
    machines are shared, and a load that drifts between the two sides would decide the ratio."""
    from engine.config import read_toml

    n, frames, size, repeats = (2, 3, "160x90", 1) if quick else (12, 60, "640x360", 2)
    seed0 = read_toml(CONFIG).get("seed", 0)
    section = SECTION.format(n=n, frames=frames, size=size)
    setups = [("2 workers x 1 thread", 2, 1)] + ([] if quick else [("2 workers x 2 threads", 2, 2)])
    seq, seq_cpu = math.inf, 0.0
    best = {}
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    with tempfile.TemporaryDirectory(prefix="particles-bench-wedge-") as tmp:
        seq_dirs = [os.path.join(tmp, "seq", f"v{k:03d}") for k in range(n)]
        for _ in range(repeats):
            seq, seq_cpu = min((seq, seq_cpu), _sequential(seq_dirs, seed0, frames, size))
            for tag, workers, threads in setups:
                out, wall, t = _wedge(tmp, f"{workers}w{threads}t", n, frames, size, workers, threads)
                t["same"] = all(_same_frames(os.path.join(out, f"v{k:03d}"), d)
                                for k, d in enumerate(seq_dirs))
                if tag not in best or wall < best[tag][0]:
                    best[tag] = (wall, t)
    rows = [Row(section, f"{n} x particles run, one after another", seq, "s",
                f"{seq / n:.2f} s per variant (process start, Taichi init, kernels, frames); "
                f"{seq_cpu:.1f} CPU s; best of {repeats}; load average {load:.1f} before")]
    for tag, workers, _ in setups:
        wall, t = best[tag]
        target = "; target <= 0.6" if workers == 2 and t["threads_per_worker"] == 1 else ""
        rows.append(Row(section, f"particles wedge, {tag}", wall, "s",
                        f"x{wall / seq:.2f} of one after another{target}; overhead "
                        f"{t['overhead_s']:.2f} s per variant (target < 0.3): cluster start "
                        f"{t['start_s']:.2f} s, Taichi start+reset {t['taichi_s_mean']:.2f} s per "
                        f"variant (+imports on the first), gap {1000 * t['gap_s_mean']:.0f} ms, sheet {1000 * t['sheet_s']:.0f} "
                        f"ms; idle tail {t['tail_idle_s']:.1f} s; kernels compiled {t['compile_s']:.1f} s; "
                        f"{t['busy_s'] / n:.2f} s inside each "
                        f"variant; {t['cpu_s']:.1f} CPU s (x{t['cpu_s'] / seq_cpu:.2f}); same bytes "
                        f"as run: {'yes' if t['same'] else 'NO'}",
                        extra={"ratio": wall / seq, "overhead_s": t["overhead_s"], "same": t["same"]}))
    return rows

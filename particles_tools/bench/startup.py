"""Cold and warm start of ``particles run configs/sparks.toml --frames 1`` as subprocesses.

Cold: Taichi's offline cache pointed (``PARTICLES_TI_CACHE``) at a fresh empty folder, so every
kernel compiles; warm: the same command again with that cache filled. Wall time of the whole
process, interpreter start and frame writing included.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

from .. import CONFIGS, ROOT
from .common import Row

CONFIG = os.path.join(CONFIGS, "sparks.toml")


def _run(cache: str, out: str) -> float:
    env = dict(os.environ, PARTICLES_TI_CACHE=cache, TI_SKIP_VERSION_CHECK="ON",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "engine", "run", CONFIG, "--frames", "1", "--out", out,
           "--overwrite", "--quiet"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=600)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"particles run failed ({p.returncode}): {p.stderr.strip()[-500:]}")
    return wall


def run(quick: bool = False):
    with tempfile.TemporaryDirectory(prefix="particles-bench-") as tmp:
        cache, out = os.path.join(tmp, "ticache"), os.path.join(tmp, "out")
        os.makedirs(cache)
        cold = _run(cache, out)
        warm = min(_run(cache, out) for _ in range(1 if quick else 3))
    sec = "start-up: particles run configs/sparks.toml --frames 1 (subprocess)"
    return [
        Row(sec, "cold (empty offline cache)", cold, "s", "every kernel compiled"),
        Row(sec, "warm (offline cache filled)", warm, "s",
            f"target <= 2 s; best of {1 if quick else 3}; x{cold / warm:.1f} faster than cold"),
    ]

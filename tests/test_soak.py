"""Soak: a long run without rendering keeps memory flat and the live-particle count steady.

Slow: excluded from the default run; ``pytest -m slow`` runs it with SOAK_FRAMES frames (default
10,000); .ci/run uses a short form. Every config in SOAK_CONFIGS that exists in configs/ runs;
at least one must.
"""
import math
import os

import numpy as np
import pytest

from engine.config import load_config
from engine.scene import Scene

pytestmark = pytest.mark.slow

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SOAK_CONFIGS = ["sparks", "campfire"]
AVAILABLE = [c for c in SOAK_CONFIGS if os.path.exists(os.path.join(ROOT, "configs", f"{c}.toml"))]
FRAMES = int(os.environ.get("SOAK_FRAMES", "10000"))
RSS_SLACK_KB = 16 * 1024


def rss_kb() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("no VmRSS in /proc/self/status")


def test_at_least_one_soak_config_exists():
    assert AVAILABLE, f"none of {SOAK_CONFIGS} in configs/"


@pytest.mark.parametrize("name", AVAILABLE)
def test_long_run_keeps_memory_flat_and_particle_count_steady(name):
    cfg = load_config(os.path.join(ROOT, "configs", f"{name}.toml"))
    scene = Scene(cfg, render=False)
    longest = max(em.lifetime for em in cfg.emitters)
    warm = max(FRAMES // 10, math.ceil(2 * longest * cfg.fps))  # pools fill within a lifetime
    assert FRAMES >= 2 * warm, f"SOAK_FRAMES={FRAMES} is too short for a {warm}-frame warm-up"
    for _ in range(warm):
        scene.advance_frame()
    before = rss_kb()
    alive = np.zeros(FRAMES - warm, np.int64)
    for k in range(FRAMES - warm):
        scene.advance_frame()
        alive[k] = scene.stats.alive
    grown = rss_kb() - before
    assert grown < RSS_SLACK_KB, f"RSS grew {grown} kB over {FRAMES - warm} frames"
    mid = float(np.median(alive))
    assert mid > 0
    assert alive.min() >= 0.75 * mid and alive.max() <= 1.25 * mid, (alive.min(), mid, alive.max())
    assert scene.dropped() == 0
    assert scene.frame == FRAMES

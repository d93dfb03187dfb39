"""Every shipped config runs its whole duration under every integrator it allows (slow; CI runs it).

A config that diverges late is a broken product: the hair config ran 20 frames in the tests and
diverged at frame 45 for its users. Here each config in configs/ runs every frame of its
duration, once per integrator it allows:

* the five ODE integrators as ``solver.integrator`` (what ``particles run --integrator`` sets:
  the particles' method and every soft body's that does not name its own);
* ``"xpbd"`` for every soft body, when the config has soft bodies;
* each of the five and ``"xpbd"`` as ``rigid.integrator`` when the config has rigid bodies and
  no joints (joints need XPBD).

Frames are drawn at a small size every few frames (the renderer's whole path, cheaply). Each run
starts a fresh Taichi program (engine.runtime.reset): a module of ~100 scenes would pass the
backend's 512 field trees.
"""
import glob
import math
import os

import numpy as np
import pytest

from engine import runtime
from engine.config import load_config
from engine.config.load import read_toml
from engine.ode.methods import INTEGRATORS

pytestmark = pytest.mark.slow

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = sorted(glob.glob(os.path.join(ROOT, "configs", "*.toml")))
DRAW_EVERY = 15  # frames between small renders
SIZE = (64, 36)


def variants(path):
    """(label, overrides dict applied to the TOML data) for every integrator the config allows."""
    data = read_toml(path)
    out = [(m, {"solver": {"integrator": m}}) for m in INTEGRATORS]
    if data.get("bodies"):
        out.append(("bodies:xpbd", {"bodies_integrator": "xpbd"}))
    if data.get("rigid_bodies") and not data.get("joints"):
        out += [(f"rigid:{m}", {"rigid": {"integrator": m}}) for m in INTEGRATORS + ("xpbd",)]
    return out


def apply(data, change):
    data = dict(data)
    for key, value in change.items():
        if key == "bodies_integrator":
            data["bodies"] = [dict(b, integrator=value) for b in data["bodies"]]
        else:
            data[key] = dict(data.get(key, {}), **value)
    return data


# the longest runs first (pytest-xdist's --dist load hands tests out in collection order: a long
# one drawn last would leave the other worker idle): hair under explicit Euler (~360k substeps,
# the stiffness guard's h for its lightly damped springs), then the rigid-body configs' cold
# compiles (measured 2026-11-26: hair-euler 512 s, debris and crates 70-230 s each, most others <40 s)
LONG_FIRST = ("hair-euler", "debris-", "crates-", "lantern-")


def _first(case_id):
    return next((k for k, p in enumerate(LONG_FIRST) if case_id.startswith(p)), len(LONG_FIRST))


CASES = sorted((pytest.param(p, label, change, id=f"{os.path.splitext(os.path.basename(p))[0]}-{label}")
                for p in CONFIGS for label, change in variants(p)), key=lambda c: _first(c.id))


def test_every_config_is_covered():
    assert len(CONFIGS) >= 10 and len(CASES) >= 5 * len(CONFIGS)


@pytest.mark.parametrize("path,label,change", CASES)
def test_config_runs_its_whole_duration(path, label, change):
    from engine.scene import Scene

    data = read_toml(path)
    data.setdefault("name", os.path.splitext(os.path.basename(path))[0])
    cfg = load_config(apply(data, change))
    frames = cfg.frames or math.ceil(cfg.duration * cfg.fps - 1e-9)
    runtime.reset()
    runtime.init("cpu")
    scene = Scene(cfg, width=SIZE[0], height=SIZE[1])
    for k in range(frames):
        scene.advance_frame()
        if k % DRAW_EVERY == 0 or k == frames - 1:
            img = scene.render()
            assert img.shape == (SIZE[1], SIZE[0], 4)
    assert scene.frame == frames
    for s in scene.systems:  # a finite end state in every system (the drivers also raise on NaN)
        d = s.drawables()
        pos = d.get("positions")
        if callable(pos):
            assert np.isfinite(pos()).all(), f"{s.name}: non-finite positions at the end"
    if scene.particles is not None:
        assert np.isfinite(scene.positions()).all()

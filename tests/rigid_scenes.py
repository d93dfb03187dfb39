"""Rigid-body scenes for the tests (tests/test_rigid*.py): a scene of bodies and joints from
config tables, and a run of it for some seconds with a callback after each frame."""
import os

from engine.config import load_config
from engine.scene import Scene

G = 9.81
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GROUND = {"type": "plane", "name": "ground", "restitution": 0.0, "friction": 0.5}


def scene(bodies, joints=(), colliders=(GROUND,), fps=60, gravity=(0.0, -G, 0.0), **rigid):
    cfg = load_config({"fps": fps, "forces": {"gravity": list(gravity)}, "colliders": list(colliders),
                       "rigid_bodies": list(bodies), "joints": list(joints), "rigid": rigid,
                       "solver": {"h": rigid.pop("solver_h", 1 / 120)} if "solver_h" in rigid else {}})
    return Scene(cfg, render=False)


def run(s, seconds, each=None):
    n = round(seconds / s.frame_dt)
    for _ in range(n):
        s.advance_frame()
        if each is not None:
            each(s)

"""Rigid rows (issue 22): boxes falling into piles on the XPBD path (ms of physics per 60 Hz
frame, timed while they pile and settle) and free bodies on the ODE path with RK4 (ms per step),
each through the scene as a game runs it (Scene.advance_frame, no rendering)."""
from __future__ import annotations

import math
import time

from .common import Row, frame_seconds

SECTION = "rigid"


def _pile_config(n: int) -> dict:
    """n boxes of 0.2 m in columns above the ground: they fall into piles."""
    side = max(1, math.ceil(math.sqrt(n / 8)))  # columns of about 8 boxes
    bodies = []
    for k in range(n):
        col, level = k % (side * side), k // (side * side)
        x, z = (col % side) * 0.5, (col // side) * 0.5
        bodies.append({"name": f"b{k}", "shape": "box", "half_extents": [0.1, 0.1, 0.1],
                       "position": [x + 0.03 * (level % 3), 0.15 + 0.3 * level, z - 0.02 * (level % 2)],
                       "orientation": [0.9962, 0.0, 0.0872 if level % 2 else 0.0, 0.0] if level % 2 else
                       [1.0, 0.0, 0.0, 0.0], "friction": 0.5, "restitution": 0.1})
    for b in bodies:  # keep the quaternions unit
        q = b["orientation"]
        s = math.sqrt(sum(c * c for c in q))
        b["orientation"] = [c / s for c in q]
    return {"fps": 60, "colliders": [{"type": "plane", "name": "ground", "friction": 0.5, "restitution": 0.1}],
            "rigid_bodies": bodies, "rigid": {"substeps": 20}}


def _free_config(n: int, steps_per_frame: int) -> dict:
    bodies = [{"name": f"f{k}", "shape": "box", "half_extents": [0.1, 0.2, 0.3],
               "position": [k % 100 * 1.0, 50.0, k // 100 * 1.0], "velocity": [0.0, 5.0, 0.0],
               "angular_velocity": [0.1, 2.0 + (k % 7) * 0.1, 0.05]} for k in range(n)]
    return {"fps": 60, "rigid_bodies": bodies, "rigid": {"integrator": "rk4"},
            "solver": {"h": 1.0 / 60.0 / steps_per_frame}}


def _mujoco_pile(data, frames):
    """ms per 60 Hz frame of the same pile in MuJoCo (the outside anchor), or None without it."""
    try:
        import mujoco
    except ImportError:
        return None
    bodies = "".join(
        f'<body pos="{b["position"][0]} {b["position"][2]} {b["position"][1]}" '
        f'quat="{b["orientation"][0]} {b["orientation"][1]} {b["orientation"][3]} {b["orientation"][2]}">'
        f'<freejoint/><geom type="box" size="0.1 0.1 0.1" density="1000" friction="0.5"/></body>'
        for b in data["rigid_bodies"])  # MuJoCo's z is up: (x, y, z) -> (x, z, y)
    xml = (f'<mujoco><option timestep="{1 / 240}"/><worldbody><geom type="plane" size="50 50 0.1" '
           f'friction="0.5"/>{bodies}</worldbody></mujoco>')
    model = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(model)
    for _ in range(4):
        mujoco.mj_step(model, d)
    t0 = time.perf_counter()
    for _ in range(frames * 4):
        mujoco.mj_step(model, d)
    return (time.perf_counter() - t0) / frames * 1e3


def _shipped(quick: bool):
    """Every shipped config with rigid bodies, stepped and rendered as `particles run` does
    (1280×720; quick: 320×180), ms per frame over its first seconds."""
    import glob
    import os

    from engine.config import load_config
    from engine.config.load import read_toml
    from engine.scene import Scene

    from .. import CONFIGS as root
    W, H = (320, 180) if quick else (1280, 720)
    out = []
    for path in sorted(glob.glob(os.path.join(root, "*.toml"))):
        data = read_toml(path)
        if not data.get("rigid_bodies"):
            continue
        s = Scene(load_config(data), width=W, height=H)
        s.advance_frame()
        ms = frame_seconds(s, 5 if quick else 60) * 1e3
        name = os.path.basename(path)[:-5]
        out.append(Row(SECTION, f"{name} (step + render {W}x{H})", ms, "ms/frame",
                       f"{1e3 / ms:.0f} fps; target >= 60 fps"))
    return out


def _scene(data):
    from engine.config import load_config
    from engine.scene import Scene

    return Scene(load_config(data), render=False)


def run(quick: bool = False):
    rows = []
    n = 100 if quick else 1000
    s = _scene(_pile_config(n))
    s.advance_frame()  # compiles
    frames = 30 if quick else 120
    t0 = time.perf_counter()
    for _ in range(frames):
        s.advance_frame()
    ms = (time.perf_counter() - t0) / frames * 1e3
    asleep = int((~s.rigid.solver.awake).sum())
    contacts = s.rigid.last_contacts.count if s.rigid.last_contacts is not None else 0
    rows.append(Row(SECTION, f"{n:,} boxes into piles (xpbd, 20 substeps)", ms, "ms/frame",
                    f"target <= 8 ms at 60 Hz; {contacts} contacts in the last step, {asleep} asleep "
                    f"after {frames + 1} frames", extra=dict(contacts=contacts, asleep=asleep)))
    mj = _mujoco_pile(_pile_config(n), frames)
    if mj is not None:
        rows.append(Row(SECTION, f"{n:,} boxes into piles (MuJoCo, 4 steps of 1/240 s)", mj, "ms/frame",
                        f"the same pile; engine / MuJoCo = {ms / mj:.2f}", extra=dict(ratio=ms / mj)))
    rows += _shipped(quick)
    n = 1000 if quick else 10_000
    per = 10
    s = _scene(_free_config(n, per))
    s.advance_frame()
    frames = 3 if quick else 10
    t0 = time.perf_counter()
    for _ in range(frames):
        s.advance_frame()
    ms = (time.perf_counter() - t0) / (frames * per) * 1e3
    rows.append(Row(SECTION, f"{n:,} free bodies, rk4 (ode path)", ms, "ms/step",
                    "target <= 2 ms per step; float64 state, one fused kernel per step"))
    return rows

"""The scenes whose behaviour tests/test_behaviour.py pins (fixtures written by make_behaviour.py)."""
import os

import numpy as np
import taichi as ti

from engine.config import load_config
from engine.scene import Scene
from helpers import scene_dict

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAME_SHOTS = {"sparks": 12, "campfire": 20, "explosion": 6, "dust": 15, "sub_emitters": 40}


def _live(scene):
    S, cap = scene.particles.state, scene.capacity
    alive = S.particle_alive.to_numpy()[:cap] != 0
    return dict(slot=np.nonzero(alive)[0].astype(np.int32),
                pos=S.particle_pos.to_numpy()[:cap][alive], vel=S.particle_vel.to_numpy()[:cap][alive],
                age=S.particle_age.to_numpy()[:cap][alive],
                emitter=S.particle_emitter.to_numpy()[:cap][alive])


SUB_EMITTERS = scene_dict(  # deaths and collisions feeding children (two of each per event)
    frames=1, fps=60, seed=3, forces={"gravity": [0.0, -9.81, 0.0]},
    emitters=[{"name": "parent", "rate": 300.0, "lifetime": 0.3, "speed": [0.5, 2.0], "spread": 60.0,
               "position": [0.0, 2.0, 0.0], "sub_emitters": [{"event": "death", "emitter": "child", "count": 2}]},
              {"name": "child", "rate": 0.0, "lifetime": 0.4, "speed": [0.1, 0.4], "spread": 180.0,
               "sub_emitters": [{"event": "collision", "emitter": "splash", "count": 2, "min_speed": 0.5}]},
              {"name": "splash", "rate": 0.0, "lifetime": 1.0, "speed": [1.0, 2.0], "spread": 45.0,
               "gravity_scale": 0.2}],
    colliders=[{"type": "plane", "point": [0.0, 1.5, 0.0], "restitution": 0.3}])


def particle_frames(name, frames):
    cfg = load_config(SUB_EMITTERS if name == "sub_emitters"
                      else os.path.join(ROOT, "configs", f"{name}.toml"))
    s = Scene(cfg, render=False)
    for _ in range(frames):
        s.advance_frame()
    return _live(s)


def _record_steps(scene):
    """The accepted step sizes of the particle system, per advance (a list per frame)."""
    return list(scene.particles.driver.step_sizes)


def adaptive_particles(frames=24):
    d = scene_dict(frames=1, fps=30, seed=4,
                   solver={"integrator": "rk4", "adaptive": True, "tolerance": 1e-6, "h": 1 / 60},
                   forces={"gravity": [0.0, -9.81, 0.0], "drag": 0.7,
                           "turbulence": {"strength": 4.0, "frequency": 2.0}},
                   emitters=[{"rate": 200.0, "lifetime": 2.0, "spread": 35.0, "speed": [2.0, 6.0],
                              "position": [0.0, 1.0, 0.0], "direction": [0.3, 1.0, 0.0],
                              "bursts": [{"time": 0.2, "count": 50}]}],
                   colliders=[{"type": "plane", "restitution": 0.6, "friction": 0.1},
                              {"type": "sphere", "center": [0.6, 0.4, 0.0], "radius": 0.3}])
    s = Scene(load_config(d), render=False)
    hs, per_frame = [], []
    for _ in range(frames):
        s.advance_frame()
        steps = _record_steps(s)
        hs += steps
        per_frame.append(len(steps))
    out = _live(s)
    out.update(h=np.array(hs), per_frame=np.array(per_frame), rejected=np.array(s.stats.rejected))
    return out


def _cloth_top():
    from engine.springs import cloth

    return cloth(10, 10, size=(0.6, 0.6), plane="xy", origin=(0.0, 1.0, 0.0), mass=0.02, ks=400.0,
                 kd=0.05, pin="corners")


def adaptive_cloth(frames=30):
    """In float64: in float32 this cloth's error estimate, a difference of positions near the
    tolerance while it has barely moved, is mostly rounding (translating it by 1e-6 m, a few ulps,
    moved its second step by 0.9 %), so the sequence was the CPU's as much as the controller's;
    in float64 a translation of 1e-9 m moves no step of its 30 frames."""
    import taichi as ti
    from engine.springs import SpringSystem

    s = SpringSystem(_cloth_top(), integrator="rk4", adaptive=True, tol=1e-5, dtype=ti.f64)
    hs, per_frame = [], []
    for _ in range(frames):
        s.step(1 / 60)
        hs += list(s.step_sizes)
        per_frame.append(len(s.step_sizes))
    return dict(h=np.array(hs), per_frame=np.array(per_frame), rejected=np.array(s.n_rejected),
                pos=s.positions())


def fixed_cloths(frames=40):
    from engine.springs import SpringSystem

    out = {}
    cfg = load_config(os.path.join(ROOT, "configs", "cloth.toml"))
    s = Scene(cfg, render=False)
    for _ in range(frames):
        s.advance_frame()
    out["xpbd"] = s.bodies[0].positions()
    for method in ("symplectic_euler", "rk4", "verlet"):
        sys = SpringSystem(_cloth_top(), integrator=method, substeps="auto")
        for _ in range(frames):
            sys.step(1 / 60)
        out[method] = sys.positions()
    return out


__all__ = ["FRAME_SHOTS", "particle_frames", "adaptive_particles", "adaptive_cloth", "fixed_cloths",
           "ti"]

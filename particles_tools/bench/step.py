"""The standard particle step (gravity + drag + ground bounce + respawn on death) three ways:

* the engine's own: a Scene built from a config, advanced by one fixed substep — the fused
  ``ParticleIntegrator.step_fixed`` kernel plus the emitter's respawn into its ring;
* a careful in-place NumPy version of the same equations (struct-of-arrays, preallocated, ``out=``);
* a STREAM-like read-modify-write of the same 32-byte state (the bandwidth limit: the fastest of
  those over the engine's own fields, slot by slot and, for a pool kept in blocks, block by
  block, and one over rows of 32 bytes, whole-row vector loads).

The pool is pre-filled in a steady state: every slot alive, ages spread so that slots die in ring
order at the emitter's rate, so each step retires and respawns rate × h particles.
"""
from __future__ import annotations

import numpy as np

from .common import Row, time_interleaved

H = 1.0 / 240.0
LIFE = 2.0
G = -9.81
DRAG = 0.5
REST = 0.5
ORIGIN = (0.0, 1.0, 0.0)


def scene_config(n: int) -> dict:
    return {
        "seed": 1, "fps": 60, "frames": 1,
        "solver": {"integrator": "symplectic_euler", "h": H},
        "forces": {"gravity": [0.0, G, 0.0], "drag": DRAG},
        "render": {"width": 64, "height": 36},
        "emitters": [{"position": list(ORIGIN), "rate": n / LIFE, "lifetime": LIFE, "capacity": n,
                      "speed": [1.0, 4.0], "spread": 30.0}],
        "colliders": [{"type": "plane", "restitution": REST, "friction": 0.0}],
    }


def initial_state(n: int, seed: int = 0):
    """Positions above the ground, velocities, and ages so that slot s dies at (s + 0.75)/rate."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform([-3, 0, -3], [3, 3, 3], (n, 3)).astype(np.float32)
    vel = rng.normal(0, 2, (n, 3)).astype(np.float32)
    rate = n / LIFE
    age = (LIFE - (np.arange(n) + 0.75) / rate).astype(np.float32)
    life = np.full(n, LIFE, np.float32)
    return pos, vel, age, life


def build_engine_scene(n: int):
    from engine.config import load_config
    from engine.scene import Scene

    scene = Scene(load_config(scene_config(n)), render=False)
    S = scene.particles.state
    pos, vel, age, life = initial_state(n)
    S.particle_pos.from_numpy(pos)
    S.particle_vel.from_numpy(vel)
    S.particle_age.from_numpy(age)
    S.particle_life.from_numpy(life)
    S.particle_alive.from_numpy(np.ones(n, np.int32))
    return scene


class NumpyStep:
    """The same step in NumPy, struct-of-arrays (rows x, y, z), no temporaries in the loop."""

    def __init__(self, n: int):
        pos, vel, age, life = initial_state(n)
        self.x = np.ascontiguousarray(pos.T)
        self.v = np.ascontiguousarray(vel.T)
        self.age, self.life = age, life
        self.tmp = np.empty((3, n), np.float32)
        self.m1 = np.empty(n, bool)
        self.m2 = np.empty(n, bool)
        rng = np.random.default_rng(1)
        self.respawn_v = rng.normal(0, 2, (3, 4096)).astype(np.float32)
        self.serial = 0

    def step(self, h=H):
        x, v, tmp, m1, m2 = self.x, self.v, self.tmp, self.m1, self.m2
        v *= np.float32(1.0 - h * DRAG)  # v += h (g − k v)
        v[1] += np.float32(h * G)
        np.multiply(v, np.float32(h), out=tmp)  # x += h v⁺ (symplectic Euler)
        x += tmp
        y, vy = x[1], v[1]
        np.less(y, 0.0, out=m1)  # ground plane: project onto it, reflect the normal velocity
        np.maximum(y, 0.0, out=y)
        np.less(vy, 0.0, out=m2)
        m2 &= m1
        t1 = tmp[0]
        np.multiply(vy, np.float32(-REST), out=t1)
        np.copyto(vy, t1, where=m2)
        self.age += np.float32(h)
        np.greater_equal(self.age, self.life, out=m1)
        dead = np.flatnonzero(m1)  # respawn at the emitter (a few per step)
        if dead.size:
            k = dead.size
            x[:, dead] = np.asarray(ORIGIN, np.float32)[:, None]
            v[:, dead] = self.respawn_v[:, (self.serial + np.arange(k)) % 4096]
            self.age[dead] = 0.0
            self.serial += k


def measure(n: int, repeats: int):
    from engine.particles import integrate
    from . import kernels

    scene = build_engine_scene(n)
    P = scene.particles
    S = P.state
    npst = NumpyStep(n)
    import taichi as ti

    rows = ti.Vector.field(8, ti.f32, shape=n)  # (the same bytes as the particles' state)
    fns = {
        "engine": lambda: scene.advance(H),
        "kernel": lambda: integrate.step_fixed(P.integrator, scene.t, H),
        "numpy": npst.step,
        "bandwidth": lambda: kernels.stream_rmw(S.particle_pos, S.particle_vel, S.particle_age,
                                                S.particle_life, 1.0, 0.0),
        "bandwidth_rows": lambda: kernels.stream_rmw_rows(rows, 1.0, 0.0)}
    if S.blocked:  # (the pool's own layout walked as the step walks it)
        fns["bandwidth_blocks"] = lambda: kernels.stream_rmw_blocks(
            S.particle_pos, S.particle_vel, S.particle_age, S.particle_life, 1.0, 0.0, P.integrator.blocks)
    t = time_interleaved(fns, repeats)
    alive = P.count_alive()
    # the limit: the fastest of the read-modify-writes (kernels.stream_rmw_rows)
    limit = min(v for k, v in t.items() if k.startswith("bandwidth"))
    return t["engine"], t["kernel"], t["numpy"], limit, alive


def run(quick: bool = False):
    sizes = (20_000, 100_000) if quick else (100_000, 1_000_000, 4_000_000)
    repeats = 5 if quick else 15
    rows = []
    for n in sizes:
        t_e, t_k, t_np, t_bw, alive = measure(n, repeats)
        bytes_moved = 64.0 * n  # 32-byte state read and written once
        label = f"{n / 1e6:g}M" if n >= 1_000_000 else f"{n // 1000}k"
        rows.append(Row("particle step", f"engine step {label}", t_e * 1e3, "ms/step",
                        f"{n / t_e / 1e6:6.0f} M upd/s  x{t_np / t_e:4.1f} NumPy  "
                        f"{100 * t_bw / t_e:3.0f}% of bandwidth limit  (live {alive:,})",
                        {"x_numpy": t_np / t_e, "pct_bw": t_bw / t_e, "n": n}))
        rows.append(Row("particle step", f"  fused kernel alone {label}", t_k * 1e3, "ms/step",
                        f"{n / t_k / 1e6:6.0f} M upd/s  x{t_np / t_k:4.1f} NumPy  "
                        f"{100 * t_bw / t_k:3.0f}% of bandwidth limit (no respawn, no Python)"))
        rows.append(Row("particle step", f"NumPy in-place {label}", t_np * 1e3, "ms/step",
                        f"{n / t_np / 1e6:6.0f} M upd/s"))
        rows.append(Row("particle step", f"bandwidth limit {label}", t_bw * 1e3, "ms/step",
                        f"{n / t_bw / 1e6:6.0f} M upd/s  {bytes_moved / t_bw / 1e9:5.1f} GB/s"))
    return rows

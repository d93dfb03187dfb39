"""The energy section: one neo-Hookean solid's forces by the closed-form path (engine.forces.elements:
P(F) written out) and by the autodiff path (engine.forces.user: the same Ψ as a user energy, Taichi
reverse mode over per-element copies), on the same tetrahedra; ms per force evaluation and their
ratio. Then the shipped configs/jelly_solid.toml as a game runs it: simulation per frame and a
1280×720 render."""
from __future__ import annotations

import os
import time

import numpy as np

from .common import Row, time_median


def run(quick: bool = False):
    import taichi as ti

    from engine.forces import terms
    from engine.forces.elements import ElementGroup
    from engine.forces.user import UserEnergy
    from engine.springs import solid

    n = 6 if quick else 14
    reps = 3 if quick else 9
    top = solid(n, n, n, size=(1.0, 1.0, 1.0), density=1000.0)
    mu, lam = terms.lame(1e5, 0.3)
    mu_s, lam_s = terms.nh_params(mu, lam)[:2]
    closed = ElementGroup("elastic", top.tets, top.positions, material=("neo_hookean", mu, lam))
    x = top.positions[top.tets]  # (T, 4, 3)
    Dm = np.stack([x[:, s] - x[:, 0] for s in (1, 2, 3)], -1)
    params = np.concatenate([np.linalg.inv(Dm).reshape(-1, 9), np.linalg.det(Dm)[:, None] / 6.0,
                             np.full((len(x), 1), mu_s), np.full((len(x), 1), lam_s)], 1)

    @ti.func
    def neo_hookean(xe, p):
        B = ti.Matrix([[p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8]]])
        Ds = ti.Matrix.cols([xe[:, 1] - xe[:, 0], xe[:, 2] - xe[:, 0], xe[:, 3] - xe[:, 0]])
        psi, P = terms.elastic_density(ti.f32, terms.NEO_HOOKEAN, Ds @ B, p[10], p[11])
        return p[9] * psi

    auto = UserEnergy(neo_hookean, top.tets, top.node_count, params, name="neo_hookean (autodiff)")
    N = top.node_count
    X, V = ti.Vector.field(3, ti.f32, N), ti.Vector.field(3, ti.f32, N)
    rng = np.random.default_rng(0)
    X.from_numpy((top.positions + 0.01 * rng.standard_normal(top.positions.shape)).astype(np.float32))
    w = ti.field(ti.f32, N)
    w.fill(1.0)
    A = ti.Vector.field(3, ti.f32, (1, N))

    def timed(g):
        def once():
            g.add_forces(X, V, w, A, 0)
            ti.sync()
        return time_median(once, reps, warmup=2)

    t_closed, t_auto = timed(closed), timed(auto)
    A.fill(0)
    closed.add_forces(X, V, w, A, 0)
    fc = A.to_numpy()[0]
    A.fill(0)
    auto.add_forces(X, V, w, A, 0)
    err = float(np.abs(A.to_numpy()[0] - fc).max() / np.abs(fc).max())
    sec = f"energy: neo-Hookean solid {n}^3 ({len(top.tets):,} tets), per force evaluation"
    rows = [Row(sec, "closed form (elements)", t_closed * 1e3, "ms/eval", "P(F) written out"),
            Row(sec, "autodiff (user energy)", t_auto * 1e3, "ms/eval",
                f"x{t_auto / t_closed:.1f} the closed form; forces agree to {err:.1e} (f32)",
                extra=dict(ratio=t_auto / t_closed))]
    rows += _shipped(quick)
    return rows


def _shipped(quick: bool):
    from engine.api import ParticleScene

    from .. import CONFIGS

    path = os.path.join(CONFIGS, "jelly_solid.toml")
    if not os.path.exists(path):
        return []
    s = ParticleScene.from_file(path)
    dt = 1.0 / 30.0
    frames = 10 if quick else 45
    for _ in range(3):  # compile the step and the render path first
        s.step(dt)
        s.render(1280, 720)
    t0 = time.perf_counter()
    for _ in range(frames):
        s.step(dt)
    t_sim = (time.perf_counter() - t0) / frames
    t0 = time.perf_counter()
    for _ in range(frames):
        s.step(dt)
        s.render(1280, 720)
    t_frame = (time.perf_counter() - t0) / frames
    sec = "energy: configs/jelly_solid.toml (216 nodes, 750 tets), per 1/30 s frame"
    return [Row(sec, "simulation", t_sim * 1e3, "ms/frame", f"{1 / t_sim:.0f} frames/s"),
            Row(sec, "simulation + 1280x720 render", t_frame * 1e3, "ms/frame", f"{1 / t_frame:.0f} frames/s")]

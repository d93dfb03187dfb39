"""Adaptive RK4 (step doubling) on a 100k-particle linear-drag scene against scipy's
``solve_ivp`` RK45 on the same 6 × N state, at equal error against the closed form
(NUMERICS.md: v = v∞ + (v₀ − v∞)e^(−t/τ), x = x₀ + v∞t + (v₀ − v∞)τ(1 − e^(−t/τ))).

The engine side is the scene's own adaptive path (``attempt``/``commit`` kernels and the
step-doubling controller) in float32; scipy integrates in float64. Each side's tolerance is the
loosest of a short ladder whose error is at or below a common target; that run is the one timed.
"""
from __future__ import annotations

import time

import numpy as np

from .common import Row

G = -9.81
K = 0.8  # 1/s: tau = 1.25 s
T_END = 2.0
TARGET_ERR = 2e-3  # m, max abs position error at T_END (float32 rounding near 20 m is ~2e-6)


def config(n: int, tol: float) -> dict:
    return {
        "seed": 5, "fps": 1.0, "frames": 1,
        "solver": {"integrator": "rk4", "adaptive": True, "tolerance": tol, "h": 0.05,
                   "max_steps_per_frame": 100000},
        "forces": {"gravity": [0.0, G, 0.0], "drag": K},
        "render": {"width": 16, "height": 16},
        "emitters": [{"rate": 1.0, "lifetime": 100.0, "capacity": n, "start": 50.0}],
    }


def initial(n: int):
    rng = np.random.default_rng(11)
    x0 = rng.uniform(-5, 5, (n, 3)).astype(np.float32)
    v0 = rng.normal(0, 8, (n, 3)).astype(np.float32)
    return x0, v0


def exact(x0, v0, t):
    tau = 1.0 / K
    vinf = np.array([0.0, G * tau, 0.0])
    e = np.exp(-t / tau)
    x = x0 + vinf * t + (v0 - vinf) * tau * (1 - e)
    v = vinf + (v0 - vinf) * e
    return x, v


def _fill(S, x0, v0):
    S.particle_pos.from_numpy(x0)
    S.particle_vel.from_numpy(v0)
    S.particle_age.fill(0.0)
    S.particle_life.fill(1e4)
    S.particle_alive.fill(1)


def run_engine(n: int, tol: float):
    from engine.config import load_config
    from engine.scene import Scene

    scene = Scene(load_config(config(n, tol)), render=False)
    x0, v0 = initial(n)
    S = scene.particles.state
    _fill(S, x0, v0)
    scene.advance(1e-4)  # compile the kernels outside the timing, then restart from t = 0
    scene.t = 0.0
    scene.particles.driver.reset()  # start again from the configured h = 0.05
    _fill(S, x0, v0)
    n0 = scene.stats.steps + scene.stats.rejected
    t0 = time.perf_counter()
    scene.advance(T_END)
    wall = time.perf_counter() - t0
    xe, _ = exact(x0.astype(np.float64), v0.astype(np.float64), T_END)
    err = float(np.abs(S.particle_pos.to_numpy() - xe).max())
    return wall, err, scene.stats.steps + scene.stats.rejected - n0


def run_scipy(n: int, rtol: float):
    from scipy.integrate import solve_ivp

    x0, v0 = initial(n)
    y0 = np.concatenate([x0.astype(np.float64).ravel(), v0.astype(np.float64).ravel()])
    g = np.zeros((n, 3))
    g[:, 1] = G
    g = g.ravel()
    m = 3 * n

    def f(t, y):
        out = np.empty_like(y)
        out[:m] = y[m:]
        np.multiply(y[m:], -K, out=out[m:])
        out[m:] += g
        return out

    t0 = time.perf_counter()
    r = solve_ivp(f, (0.0, T_END), y0, method="RK45", rtol=rtol, atol=rtol)
    wall = time.perf_counter() - t0
    xe, _ = exact(x0.astype(np.float64), v0.astype(np.float64), T_END)
    err = float(np.abs(r.y[:m, -1].reshape(n, 3) - xe).max())
    return wall, err, r.nfev


def _at_target(fn, ladder):
    """The loosest tolerance of ``ladder`` whose error is at or below TARGET_ERR (else the last)."""
    for tol in ladder:
        wall, err, work = fn(tol)
        if err <= TARGET_ERR:
            break
    return tol, wall, err, work


def run(quick: bool = False):
    n = 10_000 if quick else 100_000
    ladder = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5)[(1 if quick else 0):]
    tol_e, t_e, err_e, steps = _at_target(lambda tol: run_engine(n, tol), ladder)
    tol_s, t_s, err_s, nfev = _at_target(lambda tol: run_scipy(n, tol), ladder)
    sec = (f"adaptive RK4 vs scipy RK45, {n // 1000}k particles (6 x {n // 1000}k state), "
           f"t = 0..{T_END:g} s, error target {TARGET_ERR:g} m")
    return [
        Row(sec, "engine RK4 step doubling (f32)", t_e * 1e3, "ms",
            f"x{t_s / t_e:.0f} vs scipy (target 100); tol {tol_e:g}, max pos error {err_e:.1e} m, "
            f"{steps} attempts", {"ratio": t_s / t_e}),
        Row(sec, "scipy solve_ivp RK45 (f64)", t_s * 1e3, "ms",
            f"rtol=atol {tol_s:g}, max pos error {err_s:.1e} m, {nfev} f-evals"),
    ]

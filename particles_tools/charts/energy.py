"""Energy drift over a long fixed-step run: relative energy error against time, per method.

Two undamped systems, both through the generic :func:`engine.ode.solve`: the harmonic oscillator
(ω = 2) and a chain of :data:`CHAIN_N` unit masses joined by unit springs between two fixed walls
(a tiny ``ti.func`` over a fixed-size state). Explicit Euler's energy grows by (1 + h²ω²) per step,
midpoint's slowly, RK4's decays slowly, symplectic Euler's and Verlet's stay bounded.
"""
from typing import List

import numpy as np
import taichi as ti

from engine.ode import INTEGRATORS as METHODS, solve
from ..problems import OSCILLATOR
H = 1.0 / 64  # exactly representable; hω = 1/32 on the oscillator, hω_max < 1/32 on the chain
STEPS, QUICK_STEPS = 10000, 2000
EVERY = 10  # output every EVERY steps
CHAIN_N = 4  # masses; state (q_0..q_{N-1}, v_0..v_{N-1}); k = m = 1, so ω_max = 2 sin(Nπ/(2N+2))


@ti.func
def _chain(y, t):
    d = y * 0
    for i in ti.static(range(CHAIN_N)):
        left = y[i] * 0
        right = y[i] * 0
        if ti.static(i > 0):
            left = y[i - 1]
        if ti.static(i < CHAIN_N - 1):
            right = y[i + 1]
        d[i] = y[CHAIN_N + i]
        d[CHAIN_N + i] = left - 2.0 * y[i] + right
    return d


def chain_energy(y: np.ndarray) -> np.ndarray:
    """½ Σ v² + ½ Σ (stretch)² over the N + 1 springs, walls at q = 0; y has shape (2N, k)."""
    q, v = y[:CHAIN_N], y[CHAIN_N:]
    qq = np.concatenate([np.zeros((1,) + q.shape[1:]), q, np.zeros((1,) + q.shape[1:])])
    return 0.5 * (v ** 2).sum(0) + 0.5 * (np.diff(qq, axis=0) ** 2).sum(0)


CHAIN_Y0 = (1.0,) + (0.0,) * (2 * CHAIN_N - 1)  # first mass displaced: every mode excited

SYSTEMS = {
    "oscillator": (OSCILLATOR.f, OSCILLATOR.y0, OSCILLATOR.invariant),
    f"chain{CHAIN_N}": (_chain, CHAIN_Y0, chain_energy),
}

TITLES = {"oscillator": "harmonic oscillator, ω = 2 (hω = 1/32)",
          f"chain{CHAIN_N}": f"chain of {CHAIN_N} unit masses, unit springs, fixed ends "
                             f"(hω_max ≈ {2 * np.sin(CHAIN_N * np.pi / (2 * CHAIN_N + 2)) / 64:.3f})"}


def energy_drift(quick: bool = False) -> List[dict]:
    """Rows (system, method, step, t, energy, rel_error) for every system and method."""
    steps = QUICK_STEPS if quick else STEPS
    t_eval = H * np.arange(EVERY, steps + 1, EVERY)
    rows = []
    for system, (f, y0, energy) in SYSTEMS.items():
        e0 = float(energy(np.asarray(y0, dtype=np.float64)[:, None])[0])
        for m in METHODS:
            r = solve(f, y0, (0.0, float(t_eval[-1])), method=m, h=H, t_eval=t_eval)
            if not r.success:
                raise RuntimeError(f"energy drift: {system}/{m} failed: {r.message}")
            e = energy(r.y)
            for k, (t, ek) in enumerate(zip(r.t, e)):
                rows.append({"system": system, "method": m, "step": (k + 1) * EVERY, "t": float(t),
                             "energy": float(ek), "rel_error": float(abs(ek - e0) / e0)})
    return rows

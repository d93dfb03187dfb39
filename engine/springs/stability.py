"""Stiffness guard: the largest stable explicit step for a spring network, from its parameters.

Bounds (NUMERICS.md): ω_max² ≤ max over free nodes of 2 Σ ks / m (Gershgorin over the springs at
a node), and likewise c_max ≤ 2 Σ kd / m for the damping rate. Per method:

* symplectic Euler, Verlet: h²ω² + 2hc < 4, i.e. h < (√(c² + 4ω²) − c)/ω² (2/ω undamped).
* RK tableaus (euler, midpoint, rk4): the tableau's own stability polynomial
  R(z) = 1 + Σ_k (bᵀA^k 1) z^(k+1) must satisfy |R(hλ)| ≤ 1 for the modes λ of
  λ² + cλ + ω² = 0 with ω up to ω_max and damping proportional to stiffness, c = q ω², for the
  smallest and largest spring ratio q = kd/ks. Undamped springs (q = 0) sit on the imaginary axis,
  where Euler and midpoint are unstable for every h: the guard refuses them.
"""
import math

import numpy as np

from ..ode.tableau import TABLEAUS
from .topology import Topology

SAFETY = 0.9  # auto substeps aim at 90% of the limit


class StiffnessError(ValueError):
    """The requested step is beyond the method's stability limit for these springs."""


def network_bounds(top: Topology, pinned_mask: np.ndarray) -> dict:
    """ω_max, c_max (rad/s, 1/s) over free nodes, the worst node's stiffest spring and mass, and
    the range of kd/ks over springs."""
    n = top.node_count
    a, b = top.edges[:, 0], top.edges[:, 1]
    sum_k = np.bincount(a, top.ks, n) + np.bincount(b, top.ks, n)
    sum_c = np.bincount(a, top.kd, n) + np.bincount(b, top.kd, n)
    max_k = np.zeros(n)
    np.maximum.at(max_k, a, top.ks)
    np.maximum.at(max_k, b, top.ks)
    free = ~pinned_mask
    out = dict(omega=0.0, c=0.0, k=0.0, m=0.0, q_min=0.0, q_max=0.0)
    if not free.any() or not len(top.edges):
        return out
    w2 = np.where(free, 2 * sum_k / top.masses, 0.0)
    worst = int(np.argmax(w2))
    out.update(omega=math.sqrt(w2[worst]), c=float(np.max(np.where(free, 2 * sum_c / top.masses, 0.0))),
               k=float(max_k[worst]), m=float(top.masses[worst]))
    stiff = top.ks > 0
    if stiff.any():
        q = top.kd[stiff] / top.ks[stiff]
        out.update(q_min=float(q.min()), q_max=float(q.max()))
    return out


def stability_polynomial(method: str) -> np.ndarray:
    """Coefficients γ_0..γ_s of R(z) = Σ γ_k z^k for an explicit RK tableau."""
    tab = TABLEAUS[method]
    s = tab.stages
    A = np.zeros((s, s))
    for i, row in enumerate(tab.a):
        A[i, : len(row)] = [float(x) for x in row]
    b = np.array([float(x) for x in tab.b])
    g, v = [1.0], np.ones(s)
    for _ in range(s):
        g.append(float(b @ v))
        v = A @ v
    return np.array(g)


def _rk_limit(method: str, omega: float, q_values) -> float:
    coeffs = stability_polynomial(method)[::-1]  # highest power first for np.polyval
    if min(q_values) == 0 and abs(np.polyval(coeffs, 0.01j)) > 1:
        return 0.0  # undamped modes sit on the imaginary axis, outside this method's region
    w = omega * np.linspace(1.0 / 400, 1.0, 400)
    lams = []
    for q in q_values:
        c = q * w * w
        disc = np.sqrt((c * c - 4 * w * w).astype(complex))
        lams += [(-c + disc) / 2, (-c - disc) / 2]
    lam = np.concatenate(lams)

    def stable(h):
        return bool(np.all(np.abs(np.polyval(coeffs, h * lam)) <= 1 + 1e-12))

    lo, hi = 0.0, 8.0 / np.max(np.abs(lam))
    if stable(hi):
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def stable_step(method: str, bounds: dict) -> float:
    """Largest stable h for ``method`` given :func:`network_bounds` (inf without springs)."""
    om, c = bounds["omega"], bounds["c"]
    if om <= 0:
        return math.inf
    if method in ("symplectic_euler", "verlet"):
        return (math.sqrt(c * c + 4 * om * om) - c) / (om * om)
    return _rk_limit(method, om, sorted({bounds["q_min"], bounds["q_max"]}))


def check_step(method: str, h: float, bounds: dict, frame: float, alternative: str = "xpbd") -> None:
    """Raise :class:`StiffnessError` (one line, naming the limit) if h is beyond the stable step."""
    limit = stable_step(method, bounds)
    if h < limit:
        return
    head = f"{method} needs h < {limit:.1e} s" if limit > 0 else f"{method} is unstable at every h"
    why = (f"for ω_max = {bounds['omega']:.0f} rad/s (k = {bounds['k']:.3g}, m = {bounds['m']:.3g}"
           + (", undamped: no imaginary-axis stability" if limit <= 0 else "") + ")")
    fix = (f"use substeps >= {math.ceil(frame / (SAFETY * limit))}" if limit > 0 else "add damping kd")
    raise StiffnessError(f"{head} {why}; got h = {h:.3g}: {fix} or solver '{alternative}'")


def auto_substeps(method: str, frame: float, bounds: dict) -> int:
    """Substeps per frame keeping h at SAFETY × the stable step; raises if no h is stable."""
    limit = stable_step(method, bounds)
    if limit <= 0:
        check_step(method, frame, bounds, frame)
    return max(1, math.ceil(frame / (SAFETY * limit))) if math.isfinite(limit) else 1

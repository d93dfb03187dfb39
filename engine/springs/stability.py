"""Stiffness guard: the largest stable explicit step for a spring network, from its parameters.

Bounds (NUMERICS.md): ω_max² ≤ max over free nodes of 2 Σ ks / m (Gershgorin over the springs at
a node), and likewise c_max ≤ 2 Σ kd / m for the damping rate; the limit for those bounds comes from
the ODE core (:func:`engine.ode.stability.oscillator_stable_step`: the kick–drift closed form, or
the tableau's stability polynomial over the modes with damping proportional to stiffness for the
smallest and largest spring ratio kd/ks). Undamped springs sit on the imaginary axis, where Euler
and midpoint are unstable for every h: the guard refuses them.
"""
import math

import numpy as np

from ..ode.driver import SimulationDiverged
from ..ode.stability import oscillator_stable_step
from .topology import Topology

SAFETY = 0.9  # auto substeps aim at 90% of the limit


class StiffnessError(SimulationDiverged):
    """The requested step is beyond the method's stability limit for these springs: the run would
    diverge, so it is refused before the step (the message names the limit and the fix)."""

    def __init__(self, method: str, h: float, message: str):
        RuntimeError.__init__(self, message)
        self.method, self.h, self.t, self.kind = method, float(h), math.nan, "unstable_step"


def network_bounds(top: Topology, pinned_mask: np.ndarray, extra=None) -> dict:
    """ω_max, c_max (rad/s, 1/s) over free nodes, the worst node's stiffest spring and mass, and
    the range of kd/ks over springs. ``extra``: (k_i, c_i) per node from energy terms (Gershgorin
    row sums of their Hessians, engine.forces.elements: a spring's would be 2 ks), added to the
    springs' 2 Σ ks and 2 Σ kd; their damping ratios c_i/k_i join the kd/ks range."""
    n = top.node_count
    a, b = top.edges[:, 0], top.edges[:, 1]
    sum_k = np.bincount(a, top.ks, n) + np.bincount(b, top.ks, n)
    sum_c = np.bincount(a, top.kd, n) + np.bincount(b, top.kd, n)
    max_k = np.zeros(n)
    np.maximum.at(max_k, a, top.ks)
    np.maximum.at(max_k, b, top.ks)
    free = ~pinned_mask
    out = dict(omega=0.0, c=0.0, k=0.0, m=0.0, q_min=0.0, q_max=0.0)
    if not free.any() or not (len(top.edges) or extra is not None):
        return out
    row_k, row_c = 2 * sum_k, 2 * sum_c
    if extra is not None:
        row_k, row_c = row_k + extra[0], row_c + extra[1]
        max_k = np.maximum(max_k, 0.5 * extra[0])
    w2 = np.where(free, row_k / top.masses, 0.0)
    worst = int(np.argmax(w2))
    out.update(omega=math.sqrt(w2[worst]), c=float(np.max(np.where(free, row_c / top.masses, 0.0))),
               k=float(max_k[worst]), m=float(top.masses[worst]))
    stiff = top.ks > 0
    q = top.kd[stiff] / top.ks[stiff]
    if extra is not None:
        has = extra[0] > 0
        q = np.concatenate([q, extra[1][has] / extra[0][has]])
    if len(q):
        out.update(q_min=float(q.min()), q_max=float(q.max()))
    return out


def stable_step(method: str, bounds: dict) -> float:
    """Largest stable h for ``method`` given :func:`network_bounds` (inf without springs)."""
    return oscillator_stable_step(method, bounds["omega"], bounds["c"],
                                  sorted({bounds["q_min"], bounds["q_max"]}))


def check_step(method: str, h: float, bounds: dict, frame: float, alternative: str = "xpbd") -> None:
    """Raise :class:`StiffnessError` (one line, naming the limit) if h is beyond the stable step."""
    limit = stable_step(method, bounds)
    if h < limit:
        return
    head = f"{method} needs h < {limit:.1e} s" if limit > 0 else f"{method} is unstable at every h"
    why = (f"for ω_max = {bounds['omega']:.0f} rad/s (k = {bounds['k']:.3g}, m = {bounds['m']:.3g}"
           + (", undamped: no imaginary-axis stability" if limit <= 0 else "") + ")")
    fix = (f"use substeps >= {math.ceil(frame / (SAFETY * limit))}" if limit > 0 else "add damping kd")
    raise StiffnessError(method, h, f"{head} {why}; got h = {h:.3g}: {fix} or solver '{alternative}'")


def auto_substeps(method: str, frame: float, bounds: dict) -> int:
    """Substeps per frame keeping h at SAFETY × the stable step; raises if no h is stable."""
    limit = stable_step(method, bounds)
    if limit <= 0:
        check_step(method, frame, bounds, frame)
    return max(1, math.ceil(frame / (SAFETY * limit))) if math.isfinite(limit) else 1

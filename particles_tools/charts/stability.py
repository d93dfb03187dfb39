"""Stability chart data: largest stable h against spring stiffness, measured and predicted."""
from typing import List

import numpy as np

from engine.ode import INTEGRATORS
from engine.ode.stability import largest_stable_h_batch, numerics_formula, theory_limit

METHODS = INTEGRATORS
KDS = (0.0, 1.0, 20.0)
FULL_KS = tuple(float(v) for v in np.logspace(1, 5, 9))  # 10 … 1e5, two points per decade
QUICK_KS = (10.0, 1e3, 1e5)
STEPS = QUICK_STEPS = 20000  # quick mode only samples fewer ks
# NUMERICS.md's damped-spring table (ks = 100, m = 1): {kd: {method: h}}
NUMERICS_TABLE = {
    1.0: {"euler": 0.010, "symplectic_euler": 0.1902, "rk4": 0.2909},
    5.0: {"euler": 0.050, "symplectic_euler": 0.1562, "rk4": 0.2896},
    20.0: {"euler": 0.200, "symplectic_euler": 0.0828, "rk4": 0.2785},
}


def stability_rows(quick: bool = False) -> List[dict]:
    """One row per (method, kd, ks): measured h, step-matrix theory, NUMERICS formula (or nan)."""
    ks_list = QUICK_KS if quick else FULL_KS
    steps = QUICK_STEPS if quick else STEPS
    ks = np.array([k for _ in KDS for k in ks_list])
    kd = np.array([d for d in KDS for _ in ks_list])
    rows = []
    for m in METHODS:
        meas = largest_stable_h_batch(m, ks, kd, 1.0, steps)
        for a, b, h in zip(ks, kd, meas):
            formula = numerics_formula(m, a, b)
            rows.append({"method": m, "kd": float(b), "ks": float(a), "m": 1.0, "steps": steps,
                         "h_measured": float(h), "h_theory": theory_limit(m, a, b),
                         "h_numerics_formula": np.nan if formula is None else formula})
    return rows

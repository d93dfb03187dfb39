"""Work–precision data (Hairer & Wanner §II.10): error at T against f-evaluations and wall time.

For each reference problem: fixed-step sweeps of every method, step-doubling sweeps over tol
(rtol = tol, atol = tol·1e-3, as NUMERICS.md's table), RK4 step doubling with local
extrapolation, and scipy's ``solve_ivp`` RK45 and DOP853 with the same tolerances as the outside
anchor. The error is the max-norm error of the state at T against the closed form, or against a
DOP853 run at rtol 1e-13 where there is none (Lotka–Volterra; checked against the 8-digit value
NUMERICS.md quotes). Kepler's reference is its initial state: the orbit is periodic.
"""
import math
import time
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional

import numpy as np

from engine.ode import INTEGRATORS, METHODS, solve
from ..problems import ARENSTORF, DAMPED_SPRING, DRAG, KEPLER, KEPLER_06, LOTKA_VOLTERRA, TUMBLE_I, TUMBLING, Problem

FIELDS = ["problem", "method", "mode", "h_or_tol", "nfev", "wall_s", "error"]
FIXED_METHODS = list(INTEGRATORS)
ADAPTIVE = [(m, False) for m in INTEGRATORS] + [("rk4", True)]  # (method, local extrapolation)
SCIPY_METHODS = ["RK45", "DOP853"]


def require_scipy():
    try:
        import scipy.integrate  # noqa: F401
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError('charts need scipy and matplotlib: pip install -e ".[chart]"') from e
    return scipy.integrate


# NumPy right-hand sides for scipy, one per problem (the Taichi ti.funcs live in ode.problems).
def _drag_np(t, y):
    return np.array([y[2], y[3], -0.5 * y[2], -9.8125 - 0.5 * y[3]])


def _spring_np(t, y):
    return np.array([y[1], -100.0 * y[0] - 1.0 * y[1]])


def _lv_np(t, y):
    return np.array([1.5 * y[0] - y[0] * y[1], y[0] * y[1] - 3.0 * y[1]])


def _kepler_np(t, y):
    r3 = (y[0] * y[0] + y[1] * y[1]) ** 1.5
    return np.array([y[2], y[3], -y[0] / r3, -y[1] / r3])


_MU = 0.012277471


def _arenstorf_np(t, y):
    nu = 1 - _MU
    d1 = ((y[0] + _MU) ** 2 + y[1] ** 2) ** 1.5
    d2 = ((y[0] - nu) ** 2 + y[1] ** 2) ** 1.5
    return np.array([y[2], y[3], y[0] + 2 * y[3] - nu * (y[0] + _MU) / d1 - _MU * (y[0] - nu) / d2,
                     y[1] - 2 * y[2] - nu * y[1] / d1 - _MU * y[1] / d2])


def _qrot(q, v):
    u = q[1:]
    t = 2.0 * np.cross(u, v)
    return v + q[0] * t + np.cross(u, t)


def _tumbling_np(t, y):
    q = y[:4] / np.linalg.norm(y[:4])
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    w = _qrot(q, _qrot(conj, y[4:7]) / np.array(TUMBLE_I))
    dq = 0.5 * np.concatenate([[-w @ q[1:]], q[0] * w + np.cross(w, q[1:])])
    return np.concatenate([dq, np.zeros(4)])


@dataclass(frozen=True)
class Case:
    problem: Problem
    rhs: Callable  # NumPy f(t, y) for scipy
    n_steps: tuple  # fixed-step sweep: numbers of steps over the span (full mode)
    max_attempts: int = 40000  # adaptive runs beyond this are dropped (too slow to chart)


CASES: Dict[str, Case] = {c.problem.name: c for c in (
    Case(DRAG, _drag_np, tuple(2 ** k for k in range(2, 17))),
    Case(DAMPED_SPRING, _spring_np, tuple(2 ** k for k in range(4, 19))),
    Case(LOTKA_VOLTERRA, _lv_np, tuple(2 ** k for k in range(4, 19))),
    Case(KEPLER, _kepler_np, tuple(2 ** k for k in range(6, 20))),
    Case(KEPLER_06, _kepler_np, tuple(2 ** k for k in range(6, 19))),
    Case(ARENSTORF, _arenstorf_np, tuple(2 ** k for k in range(10, 20))),
    Case(TUMBLING, _tumbling_np, tuple(2 ** k for k in range(5, 17))),
)}
QUICK_TOLS = (1e-3, 1e-5, 1e-7, 1e-10)  # the tolerances of NUMERICS.md's table
FULL_TOLS = tuple(10.0 ** -k for k in range(2, 11))

T_LABEL = {KEPLER.name: "e = 0.9, T = 2π, one period", KEPLER_06.name: "e = 0.6, T = 2π, one period",
           ARENSTORF.name: "T = 17.065, one period",
           TUMBLING.name: "torque-free body near its middle axis, T = 4 s"}
PERIODIC = (KEPLER.name, KEPLER_06.name, ARENSTORF.name)  # the reference at T is the initial state
_ref_cache: dict = {}


def _timed(fn, repeats=3):
    """(result, seconds): the fastest of up to ``repeats`` calls while one call is under 50 ms
    (single short timings are dominated by noise on these machines)."""
    best, out = math.inf, None
    for k in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
        if best > 0.05:
            break
    return out, best


def reference_end(case: Case) -> np.ndarray:
    p = case.problem
    if p.exact is not None or p.name in PERIODIC:
        return p.y_end()
    if p.name not in _ref_cache:
        integ = require_scipy()
        s = integ.solve_ivp(case.rhs, p.t_span, p.y0, method="DOP853", rtol=1e-13, atol=1e-15)
        ref = s.y[:, -1]
        if np.abs(ref - p.y_end()).max() > 1e-8:  # the 8-digit value NUMERICS.md quotes
            raise RuntimeError(f"{p.name}: DOP853 reference {ref} disagrees with {p.y_end()}")
        _ref_cache[p.name] = ref
    return _ref_cache[p.name]


def _row(p, method, mode, x, nfev, wall, err):
    return {"problem": p.name, "method": method, "mode": mode, "h_or_tol": x, "nfev": int(nfev),
            "wall_s": wall, "error": err}


def _fixed(case: Case, method: str, n_steps, ref, repeats=3) -> List[dict]:
    p = case.problem
    T0, T1 = p.t_span
    solve(p.f, p.y0, p.t_span, method=method, h=(T1 - T0) / n_steps[0])  # compile outside timing
    rows = []
    for n in n_steps:
        h = (T1 - T0) / n
        r, wall = _timed(lambda: solve(p.f, p.y0, p.t_span, method=method, h=h), repeats)
        err = float(np.abs(r.y[:, -1] - ref).max()) if r.success else math.nan
        rows.append(_row(p, method, "fixed", h, r.nfev, wall, err))
    return rows


def _adaptive(case: Case, method: str, extrapolate: bool, tols, ref, max_attempts,
              repeats=3) -> List[dict]:
    p = case.problem
    name = method + ("+extrap" if extrapolate else "")
    kw = dict(method=method, t_eval=[p.t_span[1]], extrapolate=extrapolate)
    solve(p.f, p.y0, p.t_span, rtol=1e-1, atol=1e-4, max_steps=50, **kw)  # compile
    rows = []
    for tol in tols:  # coarse to fine: once one run is over budget, finer ones are too
        r, wall = _timed(lambda: solve(p.f, p.y0, p.t_span, rtol=tol, atol=tol * 1e-3,
                                       max_steps=max_attempts, **kw), repeats)
        if not r.success:
            break
        rows.append(_row(p, name, "adaptive", tol, r.nfev, wall,
                         float(np.abs(r.y[:, -1] - ref).max())))
    return rows


def _scipy(case: Case, method: str, tols, ref, repeats=3) -> List[dict]:
    integ = require_scipy()
    p = case.problem
    rows = []
    for tol in tols:
        s, wall = _timed(lambda: integ.solve_ivp(case.rhs, p.t_span, p.y0, method=method, rtol=tol,
                                                 atol=tol * 1e-3), repeats)
        err = float(np.abs(s.y[:, -1] - ref).max()) if s.success else math.nan
        rows.append(_row(p, "scipy " + method, "scipy", tol, s.nfev, wall, err))
    return rows


def work_precision(name: str, quick: bool = False, tols: Optional[tuple] = None) -> List[dict]:
    """All rows (dicts with :data:`FIELDS`) for the problem called ``name`` (a key of CASES)."""
    case = CASES[name]
    ref = reference_end(case)
    second = case.problem.second_order
    n_steps = case.n_steps[::3] if quick else case.n_steps
    tols = tols or (QUICK_TOLS if quick else FULL_TOLS)
    budget = case.max_attempts // 8 if quick else case.max_attempts
    rep = 1 if quick else 3
    rows: List[dict] = []
    for m in FIXED_METHODS:
        if second or not METHODS[m].partitioned:
            rows += _fixed(case, m, n_steps, ref, rep)
    for m, ex in ADAPTIVE:
        if (second or not METHODS[m].partitioned) and not (quick and m != "rk4"):
            rows += _adaptive(case, m, ex, tols, ref, budget, rep)
    for m in SCIPY_METHODS:
        rows += _scipy(case, m, tols, ref, rep)
    if name == TUMBLING.name:
        rows += mujoco_tumbling(n_steps, ref, rep)
    return rows


def mujoco_tumbling(n_steps, ref, repeats=3) -> List[dict]:
    """MuJoCo's RK4 on the same tumbling body (a free joint with the same principal inertia,
    no gravity), fixed steps over T: its state at T as (q, L_world) against the reference; 4
    derivative evaluations a step. No rows where ``mujoco`` is not installed (``pip install
    mujoco``, the ``compare`` extra)."""
    try:
        import mujoco
    except ImportError:
        return []
    p = TUMBLING
    T = p.t_span[1]
    I = np.array(TUMBLE_I)
    w0 = np.array(p.y0[4:7]) / I  # body = world at t = 0
    rows = []
    for n in n_steps:
        h = T / n
        xml = (f'<mujoco><option timestep="{h!r}" integrator="RK4" gravity="0 0 0"/><worldbody><body>'
               f'<freejoint/><inertial pos="0 0 0" mass="1" diaginertia="{I[0]} {I[1]} {I[2]}"/>'
               f'</body></worldbody></mujoco>')
        model = mujoco.MjModel.from_xml_string(xml)

        def run():
            data = mujoco.MjData(model)
            data.qvel[3:6] = w0  # a free joint's angular velocity is in the body frame
            for _ in range(n):
                mujoco.mj_step(model, data)
            return data.qpos[3:7].copy(), data.qvel[3:6].copy()

        (q, wb), wall = _timed(run, repeats)
        y = np.concatenate([q, _qrot(q, I * wb), [0.0]])
        rows.append(_row(p, "mujoco rk4", "mujoco", h, 4 * n, wall, float(np.abs(y - ref).max())))
    return rows


def fixed_slope(rows: List[dict], method: str, lo: float = 1e-11, hi: float = 1e-1) -> float:
    """Least-squares slope of log10 error against log10 nfev over a method's fixed-step points
    whose error lies in [lo, hi] (above rounding, below the pre-asymptotic range)."""
    pts = [(r["nfev"], r["error"]) for r in rows if r["method"] == method and r["mode"] == "fixed"
           and lo <= r["error"] <= hi]
    if len(pts) < 2:
        return math.nan
    x, y = np.log10(np.array(pts, dtype=np.float64)).T
    return float(np.polyfit(x, y, 1)[0])


def equal_error_ratio(rows: List[dict], method: str, anchor: str = "scipy RK45") -> List[tuple]:
    """(error, nfev ratio) for each adaptive point of ``method``: its f-evaluations over the
    anchor's at the same error (the anchor's log nfev interpolated linearly in log error between
    its two points around it; points outside the anchor's range are left out)."""
    a = sorted((r["error"], r["nfev"]) for r in rows if r["method"] == anchor and r["error"] > 0)
    if len(a) < 2:
        return []
    le, ln = np.log10([e for e, _ in a]), np.log10([n for _, n in a])
    out = []
    for r in rows:
        if r["method"] == method and r["mode"] == "adaptive" and le[0] <= math.log10(r["error"]) <= le[-1]:
            n_anchor = 10 ** float(np.interp(math.log10(r["error"]), le, ln))
            out.append((r["error"], r["nfev"] / n_anchor))
    return out

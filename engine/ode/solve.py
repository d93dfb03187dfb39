"""``solve``: a scipy-like driver for any ODE y' = f(y, t) written as a Taichi function.

The same steppers and controller serve the particle engine; this driver is the small-state path
(Lotka–Volterra, x' = −kx, reference problems for charts and tests). The state is one
``ti.Vector`` of length n held in a 0-d field; fixed-step runs loop inside one kernel, adaptive runs
launch one kernel per attempt and let the Python controller decide.
"""


import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence  # no __future__ annotations: Taichi reads them

import numpy as np
import taichi as ti

from ..runtime import ensure_init, on_reset
from .controller import StepDoublingController, clip_to_target
from .steppers import METHODS, doubling_fevals, doubling_step, is_finite, make_step, scaled_error

SUCCESS, DIVERGED, STEP_TOO_SMALL, TOO_MANY_STEPS = 0, -1, -2, -3


@dataclass
class OdeResult:
    """Outcome of :func:`solve`. ``y`` has shape (n, len(t)) as in scipy; ``status`` is 0 on
    success and negative on failure, with ``message`` saying why (method, h and t)."""

    t: np.ndarray
    y: np.ndarray
    nfev: int = 0
    n_accepted: int = 0
    n_rejected: int = 0
    status: int = SUCCESS
    message: str = "ok"
    h_last: float = math.nan
    h_history: list = field(default_factory=list, repr=False)

    @property
    def success(self) -> bool:
        return self.status == SUCCESS


class _Kernels:
    """Fields and kernels for one (f, method, n, dtype, extrapolate): built once, reused."""

    def __init__(self, f, method, n, dtype, extrapolate):
        @ti.func
        def g(y, t, i):
            return f(y, t)

        dstep = doubling_step(method, g, n, dtype, extrapolate)
        if extrapolate:  # fixed steps of local extrapolation: order p + 1
            @ti.func
            def step(y, t, h, i):
                y2, _ = dstep(y, t, h, i)
                return y2
        else:
            step = make_step(method, g, n, dtype)
        self.y = y = ti.Vector.field(n, dtype, shape=())
        self.cand = cand = ti.Vector.field(n, dtype, shape=())

        @ti.kernel
        def run_fixed(t0: dtype, h: dtype, nsteps: ti.i32) -> ti.i32:
            """Take up to nsteps steps of h; return how many ended finite."""
            done = 0
            ti.loop_config(serialize=True)
            for k in range(nsteps):
                if done == k:
                    yn = step(y[None], t0 + k * h, h, 0)
                    if is_finite(yn.sum()):
                        y[None] = yn
                        done += 1
            return done

        @ti.kernel
        def attempt(t: dtype, h: dtype, atol: dtype, rtol: dtype) -> dtype:
            y0 = y[None]
            y2, est = dstep(y0, t, h, 0)
            cand[None] = y2
            return scaled_error(y0, y2, est, atol, rtol)

        @ti.kernel
        def accept():
            y[None] = cand[None]

        @ti.kernel
        def deriv(t: dtype):
            cand[None] = g(y[None], t, 0)

        self.run_fixed, self.attempt, self.accept, self.deriv = run_fixed, attempt, accept, deriv

    def initial_step(self, t0, t1, order, atol, rtol) -> float:
        """Hairer, Nørsett & Wanner §II.4 starting step (as scipy's ``select_initial_step``):
        h0 from |y|/|f|, refined by an estimate of the second derivative. Costs 2 evaluations."""
        y0 = self.y[None].to_numpy().astype(np.float64)
        self.deriv(t0)
        f0 = self.cand[None].to_numpy().astype(np.float64)
        scale = atol + rtol * np.abs(y0)
        d0, d1 = np.max(np.abs(y0) / scale), np.max(np.abs(f0) / scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, t1 - t0)
        self.y[None] = (y0 + h0 * f0).tolist()
        self.deriv(t0 + h0)
        f1 = self.cand[None].to_numpy().astype(np.float64)
        self.y[None] = y0.tolist()
        d2 = np.max(np.abs(f1 - f0) / scale) / h0
        if not np.isfinite(d2):
            return h0
        h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
        return float(min(100 * h0, h1, t1 - t0))


_cache: dict = {}


def _drop_cache():
    _cache.clear()


on_reset(_drop_cache)


def _kernels(f, method, n, dtype, extrapolate) -> _Kernels:
    key = (f, method, n, dtype, extrapolate)
    if key not in _cache:
        _cache[key] = _Kernels(f, method, n, dtype, extrapolate)
    return _cache[key]


def solve(f: Callable, y0: Sequence[float], t_span: tuple, method: str = "rk4",
          h: Optional[float] = None, tol: Optional[float] = None, t_eval=None, dtype=ti.f64,
          rtol: Optional[float] = None, atol: Optional[float] = None, extrapolate: bool = False,
          h_min: float = 1e-12, max_steps: int = 1_000_000) -> OdeResult:
    """Integrate y' = f(y, t) from ``t_span[0]`` to ``t_span[1]``.

    f: a ``@ti.func`` taking a ``ti.Vector`` of length n = len(y0) and a scalar t, returning dy/dt.
       Python floats inside f compile at Taichi's default precision (f32): in f64 runs use exactly
       representable constants (1.5, 0.25) or read parameters from fields.
    method: ``euler``, ``midpoint``, ``rk4``, ``symplectic_euler`` or ``verlet`` (the last two need
       y = (q, p) of even length).
    h: the fixed step (without ``tol``), or the first trial step (with it).
    extrapolate: use the step-doubling result y2 + Δ/(2^p − 1) (order p + 1), with fixed or
       adaptive steps.
    tol: turns on step doubling with rtol = atol = tol unless given separately.
    t_eval: output times (sorted, inside t_span). Steps land exactly on them. Default: the end
       points for fixed steps, every accepted step for adaptive runs.
    Returns an :class:`OdeResult`; divergence (a non-finite state) is a failed status whose message
    names the method, h and t — never NaNs handed back as a result.
    """
    ensure_init()
    if method not in METHODS:
        raise ValueError(f"method: unknown value {method!r}; allowed: {', '.join(METHODS)}")
    y0 = np.asarray(y0, dtype=np.float64).ravel()
    n = y0.size
    t0, t1 = float(t_span[0]), float(t_span[1])
    if not t1 > t0:
        raise ValueError(f"t_span: need t1 > t0, got {t_span}")
    adaptive = tol is not None or rtol is not None or atol is not None
    if not adaptive and not (h and h > 0):
        raise ValueError("h: a positive fixed step is required when tol is not given")
    targets = [t1] if t_eval is None else [float(v) for v in t_eval]
    if any(b <= a for a, b in zip(targets, targets[1:])) or targets[0] < t0 or targets[-1] > t1:
        raise ValueError("t_eval: must be increasing and inside t_span")
    meth = METHODS[method]
    K = _kernels(f, method, n, dtype, bool(extrapolate))
    K.y[None] = y0.tolist()
    ts, ys = ([t0], [y0.copy()]) if (t_eval is None or targets[0] == t0) else ([], [])
    res = OdeResult(t=np.empty(0), y=np.empty((n, 0)))
    t = t0
    targets = [v for v in targets if v > t0]

    def fail(status, msg):
        res.status, res.message = status, msg

    if not adaptive:
        for target in targets:
            nsteps = max(1, math.ceil((target - t) / h - 1e-9))
            hh = (target - t) / nsteps  # equal steps that land exactly on the target
            done = K.run_fixed(t, hh, nsteps)
            res.nfev += done * (doubling_fevals(method) if extrapolate else meth.fevals)
            res.n_accepted += done
            res.h_last = hh
            if done < nsteps:
                fail(DIVERGED, f"{method} diverged: non-finite state at t={t + (done + 1) * hh:.6g} "
                               f"with h={hh:.6g}")
                break
            t = target
            ts.append(t)
            ys.append(K.y[None].to_numpy().astype(np.float64))
    else:
        rt = tol if rtol is None else rtol
        at = (tol if tol is not None else rt) if atol is None else atol
        ctrl = StepDoublingController(order=meth.order, h_min=h_min)
        if h:
            hh = h
        else:
            hh = K.initial_step(t0, t1, meth.order, at, rt)
            res.nfev += 2
        for target in targets:
            while t < target and res.status == SUCCESS:
                if res.n_accepted + res.n_rejected >= max_steps:
                    fail(TOO_MANY_STEPS, f"{method}: gave up after {max_steps} steps at t={t:.6g}")
                    break
                hs, lands = clip_to_target(t, hh, target)
                err = K.attempt(t, hs, at, rt)
                res.nfev += doubling_fevals(method)
                ok, h_new = ctrl.propose(hs, err)
                if ok:
                    K.accept()
                    t = target if lands else t + hs
                    res.n_accepted += 1
                    res.h_last = hs
                    res.h_history.append(hs)
                    if t_eval is None and t < target:
                        ts.append(t)
                        ys.append(K.y[None].to_numpy().astype(np.float64))
                    # a landing step was clipped: resume from the step the controller wanted
                    hh = max(h_new, hh) if lands else h_new
                else:
                    res.n_rejected += 1
                    hh = h_new
                    if hh < h_min:
                        kind = "non-finite error estimate" if not math.isfinite(err) else "error too large"
                        fail(STEP_TOO_SMALL if math.isfinite(err) else DIVERGED,
                             f"{method}: step size fell below h_min={h_min:g} at t={t:.6g} "
                             f"(h={hs:.6g}, {kind}); the problem may be stiff or diverging")
            if res.status != SUCCESS:
                break
            ts.append(t)
            ys.append(K.y[None].to_numpy().astype(np.float64))
    res.t = np.asarray(ts)
    res.y = np.asarray(ys).T.reshape(n, len(ts))
    return res

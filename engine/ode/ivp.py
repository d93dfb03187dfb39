"""``solve`` (initial value problems): a scipy-like front end for any ODE y' = f(y, t) written as a Taichi function.

The small-state system (Lotka–Volterra, x' = −kx, the reference problems of charts and tests):
the state is one ``ti.Vector`` of length n in a 0-d field, stepped by the same ``ti.func``
steppers as the particles and advanced by the same :class:`~engine.ode.driver.Driver`. Fixed steps
loop inside one kernel (one launch per output interval); adaptive runs launch one kernel per
attempt and the driver's controller decides.
"""


import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence  # no __future__ annotations: Taichi reads them

import numpy as np
import taichi as ti

from ..runtime import ensure_init, on_reset
from .driver import NONFINITE, STEP_TOO_SMALL as _TOO_SMALL, Driver, SimulationDiverged, StepPolicy
from .methods import method as _method
from .events import doubling_error, fixed_error, located_step
from .steppers import doubling_step, is_finite, make_step

MAX_EVENT_RECORDS = 10_000  # event times kept per solve (OdeResult.t_events)
EVENT_TOL = 0.01  # adaptive runs locate an event to 1% of atol (fixed steps: to rounding)

SUCCESS, DIVERGED, STEP_TOO_SMALL, TOO_MANY_STEPS = 0, -1, -2, -3


@dataclass
class OdeResult:
    """Outcome of :func:`solve`. ``y`` has shape (n, len(t)) as in scipy; ``status`` is 0 on
    success and negative on failure, with ``message`` saying why (method, h and t);
    ``t_events``: when events were located (solve's ``events``)."""

    t: np.ndarray
    y: np.ndarray
    nfev: int = 0
    n_accepted: int = 0
    n_rejected: int = 0
    status: int = SUCCESS
    message: str = "ok"
    h_last: float = math.nan
    h_history: list = field(default_factory=list, repr=False)
    t_events: np.ndarray = field(default_factory=lambda: np.empty(0))

    @property
    def success(self) -> bool:
        return self.status == SUCCESS


class _Kernels:
    """Fields and kernels for one (f, method, n, dtype, extrapolate, events): built once, reused."""

    def __init__(self, f, method, n, dtype, extrapolate, events):
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
        fixed, doubled = fixed_error(step, dtype), doubling_error(dstep)
        located = events is not None
        if located:  # the same event location as the particles' (engine.ode.events)
            fixed = located_step(fixed, events, n, dtype)
            doubled = located_step(doubled, events, n, dtype)
        self.y = y = ti.Vector.field(n, dtype, shape=())
        self.cand = cand = ti.Vector.field(n, dtype, shape=())
        self.t_events = t_events = ti.field(dtype, shape=MAX_EVENT_RECORDS if located else 1)
        self.n_events = n_events = ti.field(ti.i32, shape=())  # accepted steps with an event
        self.located = located_count = ti.field(ti.i32, shape=())  # events located in every attempt
        cand_event = ti.field(dtype, shape=())

        @ti.func
        def advance(stepper: ti.template(), y0, t, h, atol, rtol, tol_g):
            """(y, err, events located, time of the step's fastest event or −1) for one step."""
            t_ev, yn, err = ti.cast(-1.0, dtype), y0, ti.cast(0.0, dtype)
            count = 0
            if ti.static(located):
                yn, err, count, which, lag, _x, _n, _s, _dv, _stop = stepper(y0, t, h, 0, atol, rtol, tol_g)
                if count > 0:  # (not a contact held at the step's end)
                    t_ev = t + h - lag
            else:
                yn, err = stepper(y0, t, h, 0, atol, rtol)
            return yn, err, count, t_ev

        @ti.func
        def record(t_ev):
            if t_ev >= 0.0:
                c = n_events[None]
                if c < MAX_EVENT_RECORDS:
                    t_events[c] = t_ev
                n_events[None] = c + 1

        @ti.kernel
        def run_fixed(t0: dtype, h: dtype, nsteps: ti.i32) -> ti.i32:
            """Take up to nsteps steps of h; return how many ended finite."""
            done = 0
            ti.loop_config(serialize=True)  # one small state, step after step (not a per-frame kernel)
            for k in range(nsteps):
                if done == k:
                    yn, _err, count, t_ev = advance(fixed, y[None], t0 + k * h, h, 1.0, 1.0, 0.0)
                    located_count[None] += count
                    if is_finite(yn.sum()):
                        y[None] = yn
                        record(t_ev)
                        done += 1
            return done

        @ti.kernel
        def attempt(t: dtype, h: dtype, atol: dtype, rtol: dtype) -> dtype:
            yn, err, count, t_ev = advance(doubled, y[None], t, h, atol, rtol, EVENT_TOL * atol)
            cand[None] = yn
            cand_event[None] = t_ev
            located_count[None] += count
            return err

        @ti.kernel
        def accept():
            y[None] = cand[None]
            record(cand_event[None])

        @ti.kernel
        def deriv(t: dtype):
            cand[None] = g(y[None], t, 0)

        self.run_fixed, self.attempt, self.accept, self.deriv = run_fixed, attempt, accept, deriv

    def events(self) -> np.ndarray:
        n = min(int(self.n_events[None]), MAX_EVENT_RECORDS)
        return self.t_events.to_numpy()[:n].astype(np.float64)


_cache: dict = {}


def _drop_cache():
    _cache.clear()


on_reset(_drop_cache)


def _kernels(f, method, n, dtype, extrapolate, events) -> _Kernels:
    key = (f, method, n, dtype, extrapolate, id(events))
    if key not in _cache:
        _cache[key] = _Kernels(f, method, n, dtype, extrapolate, events)
    return _cache[key]


class _SmallSystem:
    """The driver's protocol over one small state. ``outputs``: when a list, (t, y) is appended
    after every accepted step (solve without t_eval)."""

    def __init__(self, K: _Kernels, method: str, order: int, atol: float, rtol: float, outputs=None):
        self.K, self.method, self.label, self.order = K, method, method, order
        self.atol, self.rtol, self.outputs = atol, rtol, outputs
        self._bad = None

    def y(self) -> np.ndarray:
        return self.K.y[None].to_numpy().astype(np.float64)

    def fixed_step(self, t0, h, j, n):
        t = t0 + j * h
        done = self.K.run_fixed(t, h, n - j)
        if done < n - j and self._bad is None:
            self._bad = t + (done + 1) * h
        return n - j

    def attempt(self, t, h):
        return float(self.K.attempt(t, h, self.atol, self.rtol))

    def commit(self, t, h):
        self.K.accept()
        if self.outputs is not None:
            self.outputs.append((t + h, self.y()))

    def rollback(self):
        pass  # the trial sits in `cand` until accepted

    def first_nonfinite(self):
        bad, self._bad = self._bad, None
        return bad

    def first_step(self, t0, t1) -> float:
        """Hairer, Nørsett & Wanner §II.4 starting step (as scipy's ``select_initial_step``):
        h0 from |y|/|f|, refined by an estimate of the second derivative. Costs 2 evaluations."""
        K, atol, rtol = self.K, self.atol, self.rtol
        y0 = self.y()
        K.deriv(t0)
        f0 = K.cand[None].to_numpy().astype(np.float64)
        scale = atol + rtol * np.abs(y0)
        d0, d1 = np.max(np.abs(y0) / scale), np.max(np.abs(f0) / scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, t1 - t0)
        K.y[None] = (y0 + h0 * f0).tolist()
        K.deriv(t0 + h0)
        f1 = K.cand[None].to_numpy().astype(np.float64)
        K.y[None] = y0.tolist()
        d2 = np.max(np.abs(f1 - f0) / scale) / h0
        if not np.isfinite(d2):
            return h0
        h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1.0 / (self.order + 1))
        return float(min(100 * h0, h1, t1 - t0))


def solve(f: Callable, y0: Sequence[float], t_span: tuple, method: str = "rk4",
          h: Optional[float] = None, tol: Optional[float] = None, t_eval=None, dtype=ti.f64,
          rtol: Optional[float] = None, atol: Optional[float] = None,
          extrapolate: Optional[bool] = None, h_min: float = 1e-12, max_steps: int = 1_000_000,
          events=None) -> OdeResult:
    """Integrate y' = f(y, t) from ``t_span[0]`` to ``t_span[1]``.

    f: a ``@ti.func`` taking a ``ti.Vector`` of length n = len(y0) and a scalar t, returning dy/dt.
       Python floats inside f compile at Taichi's default precision (f32): in f64 runs use exactly
       representable constants (1.5, 0.25) or read parameters from fields.
    method: ``euler``, ``midpoint``, ``rk4``, ``symplectic_euler`` or ``verlet`` (the last two need
       y = (q, p) of even length).
    h: the fixed step (without ``tol``), or the first trial step (with it).
    extrapolate: use the step-doubling result y2 + Δ/(2^p − 1) (order p + 1), with fixed or
       adaptive steps. Default: with adaptive steps (measured: at equal error it needs fewer
       evaluations on every reference problem — README, "What the tolerance bounds"), not with
       fixed ones.
    tol: turns on step doubling with rtol = atol = tol unless given separately; what it bounds:
       every accepted step's estimated local error, max over components of
       |est_i| / (atol + rtol·max(|y_i|, |y_new_i|)) ≤ 1.
    events: an event set located inside every step (:mod:`engine.ode.events`; e.g. an
       :class:`engine.colliders.Colliders` of dtype ``dtype``) for a second-order state
       y = (q, p), q' = p, whose first three components of q are a point: the point bounces.
       ``OdeResult.t_events`` holds the time of each step's fastest event.
    t_eval: output times (sorted, inside t_span). Steps land exactly on them. Default: the end
       points for fixed steps, every accepted step for adaptive runs.
    h_min, max_steps: the driver gives up when a rejection would take h below h_min, or after
       max_steps attempts in all.
    Returns an :class:`OdeResult`; divergence (a non-finite state) is a failed status whose message
    names the method, h and t — never NaNs handed back as a result.
    """
    ensure_init()
    meth = _method(method)
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
    if extrapolate is None:
        extrapolate = adaptive
    if events is not None:
        if n % 2 or n < 6:
            raise ValueError(f"events: need a second-order state (q, p) with a 3-D point, got {n} components")
        if any(events.stops(k) for k in range(events.event_count)):
            raise ValueError("events: an event that stops the motion (a kill collider) is not supported here")
    K = _kernels(f, method, n, dtype, bool(extrapolate), events)
    K.n_events[None] = 0
    K.located[None] = 0
    K.y[None] = y0.tolist()
    ts, ys = ([t0], [y0.copy()]) if (t_eval is None or targets[0] == t0) else ([], [])
    rt = tol if rtol is None else rtol
    at = (tol if tol is not None else rt) if atol is None else atol
    every_step = adaptive and t_eval is None
    outputs = [] if every_step else None
    system = _SmallSystem(K, method, meth.order, at, rt, outputs)
    driver = Driver(system, StepPolicy(h=h, adaptive=adaptive, h_min=h_min))
    res = OdeResult(t=np.empty(0), y=np.empty((n, 0)))
    if adaptive and not h:
        res.nfev += 2  # the first-step estimate
    per_step = (meth.doubling_fevals if (adaptive or extrapolate) else meth.fevals)
    t, h_seen = t0, []

    def keep_outputs(upto):
        ts.extend(p[0] for p in outputs[:upto])
        ys.extend(p[1] for p in outputs[:upto])
        outputs.clear()

    try:
        for target in (v for v in targets if v > t0):
            driver.advance(t, target, max_steps=max_steps - driver.stats.steps - driver.stats.rejected)
            h_seen += driver.step_sizes
            t = target
            if outputs is not None:
                keep_outputs(-1)  # the last one is the target itself, appended next
            ts.append(t)
            ys.append(system.y())
    except SimulationDiverged as e:
        h_seen += driver.step_sizes
        if outputs is not None:
            keep_outputs(None)
        res.status = {NONFINITE: DIVERGED, _TOO_SMALL: STEP_TOO_SMALL}.get(e.kind, TOO_MANY_STEPS)
        res.message = str(e)
    st = driver.stats
    res.n_accepted, res.n_rejected = st.steps, st.rejected
    res.nfev += per_step * (st.steps + st.rejected + 2 * int(K.located[None]))  # an event: two more steps
    res.t_events = K.events() if events is not None else np.empty(0)
    res.h_history = h_seen if adaptive else []
    res.h_last = h_seen[-1] if h_seen else math.nan
    res.t = np.asarray(ts)
    res.y = np.asarray(ys).T.reshape(n, len(ts))
    return res

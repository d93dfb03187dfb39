"""The one time-stepping loop: fixed substeps or step doubling, over a small protocol.

Particles, spring networks and :func:`engine.ode.solve` are *systems*: they know how to take a
step and estimate its error, the driver decides which steps to take (scipy's ``OdeSolver.step``
and diffrax's ``diffeqsolve`` split the work the same way). The protocol:

* ``label`` (names the system in messages), ``method`` and ``order`` (the controller's exponent);
* ``fixed_step(t0, h, j, n) -> k``: fixed stepping, steps j, j+1, … (< n) of the n steps of h
  from t0 (step m starts at t0 + m·h); returns how many it took, k ≥ 1: one where the system's
  host work sits between steps, a run of them where nothing has to happen in between (a
  particle run with no births due, solve's whole interval in one kernel);
* ``attempt(t, h) -> err``: a trial step from the committed state at t, kept aside, returning the
  scaled max-norm error estimate (≤ 1 accepts; NaN or inf is a rejection);
* ``commit(t, h)`` makes the trial the state; ``rollback()`` discards it;
* ``first_nonfinite() -> t or None``: the end time of the first step since the last call that left
  a non-finite state (read once per ``advance``: no per-step host round trip);
* optional ``first_step(t, t_end) -> h``: a first trial step when the policy gives none;
* optional ``locate(t, h) -> tau or None``: an event inside an accepted trial step (a collision);
  the driver then cuts the step to end at t + tau, so a system can resolve the event at its time
  before going on. The built-in systems do not use it: their impacts are located per element
  inside the step (:mod:`engine.ode.events`), so a pool's step is not cut once per contact.

Policy, one for all systems (:class:`StepPolicy`): fixed steps are :func:`substeps` (span, h)
equal substeps landing exactly on the target; adaptive steps start from the policy's h (or the system's
``first_step``), are clipped to land on the target without a sliver (:func:`clip_to_target`),
resume after a clipped landing from the step the controller wanted before clipping, stay at most
``h_max``, count every attempt against ``max_steps`` per advance, and give up with
:class:`SimulationDiverged` when a rejection would take h below ``h_min``. The stop check
(``engine.runtime.check_stop``) runs once per call into the system: once per attempted step,
once per fixed step or run of fixed steps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from ..runtime import check_stop
from .controller import StepDoublingController

H_REL_TOL = 1e-6  # span / h this close (relatively) to a whole number counts as that number


def substeps(span: float, h: float) -> int:
    """How many equal substeps of about h (s) cover ``span`` (s): ceil(span / h), except that a
    span / h within a relative 1e-6 of a whole number n is n steps — so an h written to seven
    digits lands as it was meant: h = 0.008333333 (1/120) takes a 1/60 s frame in 2 steps, not 3
    of 1/180 s (span / h = 2.00000008), and a 1/30 s frame in 4, not 5. A step is then at most
    h·(1 + 1e-6) long. Every fixed-step count in the engine (particles, soft bodies, rigid bodies,
    the coupler, the run's estimates) comes from here."""
    x = span / h
    n = round(x)
    if n >= 1 and abs(x - n) <= H_REL_TOL * x:
        return n
    return max(1, math.ceil(x))

NONFINITE, STEP_TOO_SMALL, TOO_MANY_STEPS = "nonfinite", "step_too_small", "too_many_steps"


class SimulationDiverged(RuntimeError):
    """The simulation failed: a non-finite state, a step size collapsing below h_min, or more
    steps than allowed. Carries ``method``, ``h`` and ``t`` (s) and ``kind`` (one of NONFINITE,
    STEP_TOO_SMALL, TOO_MANY_STEPS); the message names all of them in one line."""

    def __init__(self, label: str, method: str, h: float, t: float, reason: str,
                 kind: str = NONFINITE):
        self.method, self.h, self.t, self.kind = method, float(h), float(t), kind
        super().__init__(f"{label} diverged: {reason} at t={t:.6g} s with h={h:.4g} s")


@dataclass
class StepPolicy:
    """``h``: the fixed step (fixed stepping) or the first trial step (adaptive; None: the
    system's ``first_step``, else the whole span). ``max_steps``: attempts per ``advance``;
    ``max_steps_hint``: what to change when it is exceeded (a config key)."""

    h: Optional[float] = None
    adaptive: bool = False
    rtol: float = 1e-3
    atol: float = 1e-3
    h_min: float = 1e-12
    h_max: float = math.inf
    max_steps: int = 1_000_000
    max_steps_hint: str = ""


@dataclass
class DriverStats:
    """Accepted steps, rejected attempts and the range of accepted step sizes, over all advances."""

    steps: int = 0
    rejected: int = 0
    h_min: float = math.inf
    h_max: float = 0.0


def clip_to_target(t: float, h: float, t_target: float) -> tuple[float, bool]:
    """Shorten h so a step lands exactly on ``t_target`` without leaving a sliver step.

    Returns (h, lands). If h reaches the target (within 1%), take exactly the remainder; if two
    steps of h would overshoot, split the remainder in two equal steps instead of one step plus a
    sliver."""
    rem = t_target - t
    if h >= rem * 0.99:
        return rem, True
    if 2.0 * h > rem:
        return rem / 2.0, False
    return h, False


class Driver:
    """Advances one system under one :class:`StepPolicy`. ``step_sizes``: the accepted h of the
    last ``advance``; ``h_next``: the trial step the next adaptive advance starts from."""

    def __init__(self, system, policy: StepPolicy, stats: Optional[DriverStats] = None):
        self.system, self.policy = system, policy
        self.stats = stats if stats is not None else DriverStats()
        self.controller = StepDoublingController(order=system.order) if policy.adaptive else None
        self.h_next = None
        self.step_sizes: list = []

    def reset(self) -> None:
        """Forget the trial step carried between advances: the next starts as the first did."""
        self.h_next = None
        if self.controller is not None:
            self.controller = StepDoublingController(order=self.system.order)

    def advance(self, t: float, t_end: float, max_steps: Optional[int] = None) -> None:
        """Advance the system from t to exactly t_end (> t)."""
        if self.policy.adaptive:
            self._adaptive(t, t_end, self.policy.max_steps if max_steps is None else max_steps)
        else:
            self._fixed(t, t_end)
        bad = self.system.first_nonfinite()
        if bad is not None:
            h = self.step_sizes[-1] if self.step_sizes else (self.h_next or t_end - t)
            raise SimulationDiverged(self.system.label, self.system.method, h, bad, "non-finite state")

    def _record(self, h: float) -> None:
        st = self.stats
        st.steps += 1
        st.h_min, st.h_max = min(st.h_min, h), max(st.h_max, h)
        self.step_sizes.append(h)

    def _fixed(self, t: float, t_end: float) -> None:
        n = substeps(t_end - t, self.policy.h)
        h = (t_end - t) / n  # equal substeps that land exactly on the target
        self.step_sizes = []
        j = 0
        while j < n:
            check_stop()
            k = self.system.fixed_step(t, h, j, n)
            for _ in range(k):
                self._record(h)
            j += k

    def _first_step(self, t: float, t_end: float) -> float:
        if self.h_next is not None:
            return self.h_next
        if self.policy.h:
            return self.policy.h
        first = getattr(self.system, "first_step", None)
        return first(t, t_end) if first is not None else t_end - t

    def _adaptive(self, t: float, t_end: float, max_steps: int) -> None:
        sys, pol, ctrl = self.system, self.policy, self.controller
        h_try = self._first_step(t, t_end)
        self.step_sizes = []
        attempts = 0
        locate = getattr(sys, "locate", None)
        while t < t_end:
            check_stop()
            if attempts >= max_steps:
                raise SimulationDiverged(sys.label, sys.method, h_try, t,
                                         f"more than {max_steps} steps before t={t_end:.6g} s"
                                         + (f" ({pol.max_steps_hint})" if pol.max_steps_hint else ""),
                                         TOO_MANY_STEPS)
            h, lands = clip_to_target(t, h_try, t_end)
            err = sys.attempt(t, h)
            attempts += 1
            ok, h_new = ctrl.propose(h, err)
            if not ok:
                sys.rollback()
                self.stats.rejected += 1
                h_try = h_new
                if h_new < pol.h_min:
                    finite = math.isfinite(err)
                    raise SimulationDiverged(
                        sys.label, sys.method, h, t,
                        f"step size fell below h_min={pol.h_min:g} (error estimate {err:.3g})",
                        STEP_TOO_SMALL if finite else NONFINITE)
                continue
            tau = locate(t, h) if locate is not None else None
            if tau is not None and 0.0 < tau < h:  # an event inside the step: end it there
                sys.rollback()
                sys.attempt(t, tau)  # a shorter step than an accepted one: accepted too
                h, lands = tau, False
            sys.commit(t, h)
            t = t_end if lands else t + h
            self._record(h)
            # after a step clipped to land, resume from the step the controller wanted
            h_try = min(pol.h_max, max(h_new, h_try) if lands else h_new)
        self.h_next = h_try

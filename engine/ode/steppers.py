"""One-step methods as Taichi functions, generated from data at compile time.

Every stepper here has the signature ``step(y, t, h, i) -> y_next`` where ``y`` is a
``ti.Vector`` of any length n, ``t`` and ``h`` are scalars of the state's dtype and ``i`` is an
opaque integer context (an element index in a batch) handed through to the derivative
``f(y, t, i) -> dy/dt``. The steppers know nothing else: not particles, not springs.

* :func:`rk_step` runs any :class:`~engine.ode.tableau.ButcherTableau`; stages are unrolled with
  ``ti.static`` so a tableau costs exactly its stages and adding a method means adding data.
* :func:`symplectic_euler_step` and :func:`verlet_step` are partitioned methods for second-order
  systems y = (q, p): the first half of y is the position-like part, the second half the
  velocity-like part (for particles q = x, p = v, f = (v, a(x, v, t))).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import taichi as ti

from .tableau import TABLEAUS, ButcherTableau


def _with_first_eval(_step, f, with_k1: bool):
    """``_step(y, t, h, i, d1)`` takes f(y, t) precomputed (step doubling shares it between the
    full step and the first half step); the plain stepper evaluates it itself."""
    if with_k1:
        return _step

    @ti.func
    def step(y, t, h, i):
        return _step(y, t, h, i, f(y, t, i))

    return step


def rk_step(tab: ButcherTableau, f: Callable, dtype, with_k1: bool = False):
    """Explicit RK step for ``tab``. With ``with_k1`` the function takes ``f(y, t, i)`` precomputed
    as a fifth argument (step doubling shares it between the full step and the first half step).

    Each coefficient is emitted as cast(numerator)/cast(denominator) in ``dtype``: exact for the
    rational tableaus, and an f64 kernel never sees a constant rounded through Taichi's f32."""
    s = tab.stages
    nd = lambda q: (q.numerator, q.denominator)  # noqa: E731
    A = tuple(tuple(nd(q) for q in row) for row in tab.a)
    C = tuple(nd(q) for q in tab.c)
    B = tuple(nd(q) for q in tab.b)

    @ti.func
    def _step(y, t, h, i, d1):
        ks = [d1] * s  # derivatives f(Y_j, t + c_j h), one per stage (a Python list, unrolled)
        for j in ti.static(range(1, s)):
            yj = y
            for m in ti.static(range(j)):
                if ti.static(A[j][m][0] != 0):
                    yj = yj + (h * ti.cast(A[j][m][0], dtype) / ti.cast(A[j][m][1], dtype)) * ks[m]
            tj = t + h * ti.cast(C[j][0], dtype) / ti.cast(C[j][1], dtype)
            ks[j] = f(yj, tj, i)
        out = y
        for j in ti.static(range(s)):
            if ti.static(B[j][0] != 0):
                out = out + (h * ti.cast(B[j][0], dtype) / ti.cast(B[j][1], dtype)) * ks[j]
        return out

    return _with_first_eval(_step, f, with_k1)


def _half_masks(n: int, dtype):
    if n % 2:
        raise ValueError(f"partitioned methods need an even state length (q, p); got {n}")
    m = n // 2
    return [1] * m + [0] * m, [0] * m + [1] * m


def symplectic_euler_step(f: Callable, n: int, dtype, with_k1: bool = False, fq=None):
    """Semi-implicit Euler: p⁺ = p + h f_p(q, p, t); q⁺ = q + h f_q(q, p⁺, t). Order 1, symplectic.

    For particles: v⁺ = v + h a(x, v, t), x⁺ = x + h v⁺. Two evaluations of f per step; the second
    needs only its q-part, so a caller that has a cheap ``fq`` (for particles: just v) passes it
    and the expensive p-part (forces) is evaluated once."""
    mq, mp = _half_masks(n, dtype)
    fq = fq or f

    @ti.func
    def _step(y, t, h, i, d1):
        Mq = ti.Vector(mq, dt=dtype)
        Mp = ti.Vector(mp, dt=dtype)
        y1 = y + h * (Mp * d1)
        return y1 + h * (Mq * fq(y1, t, i))

    return _with_first_eval(_step, f, with_k1)


def verlet_step(f: Callable, n: int, dtype, with_k1: bool = False, fq=None):
    """Velocity Verlet (Störmer–Verlet, kick–drift–kick):
    p½ = p + h/2 f_p(q, p, t); q⁺ = q + h f_q(q, p½, t + h/2); p⁺ = p½ + h/2 f_p(q⁺, p½, t + h).

    Order 2 and symplectic when f_p depends on q only. Velocity-dependent forces (drag) enter the
    closing kick as f_p(q⁺, p½): the explicit form, which drops to order 1 for such forces
    (NUMERICS.md); the exact form would need an implicit solve for p⁺. The drift needs only the
    q-part of f: pass a cheap ``fq`` to skip the forces there."""
    mq, mp = _half_masks(n, dtype)
    fq = fq or f

    @ti.func
    def _step(y, t, h, i, d1):
        Mq = ti.Vector(mq, dt=dtype)
        Mp = ti.Vector(mp, dt=dtype)
        half = h / 2
        y1 = y + half * (Mp * d1)
        y2 = y1 + h * (Mq * fq(y1, t + half, i))
        return y2 + half * (Mp * f(y2, t + h, i))

    return _with_first_eval(_step, f, with_k1)


@dataclass(frozen=True)
class Method:
    """What the solver and controller need to know about a method: its order and its cost."""

    name: str
    order: int
    fevals: int  # derivative evaluations per step
    partitioned: bool  # needs y = (q, p)
    symplectic: bool


METHODS = {
    "euler": Method("euler", 1, 1, False, False),
    "midpoint": Method("midpoint", 2, 2, False, False),
    "rk4": Method("rk4", 4, 4, False, False),
    "symplectic_euler": Method("symplectic_euler", 1, 2, True, True),
    "verlet": Method("verlet", 2, 3, True, True),
}
assert all(METHODS[t].order == TABLEAUS[t].order and METHODS[t].fevals == TABLEAUS[t].stages
           for t in TABLEAUS)


def make_step(method: str, f: Callable, n: int, dtype, with_k1: bool = False, fq=None):
    """The ``ti.func`` stepper for ``method`` (one of :data:`METHODS`) on states of length n.
    ``fq`` (partitioned methods only) evaluates just the q-part of f cheaply."""
    if method in TABLEAUS:
        return rk_step(TABLEAUS[method], f, dtype, with_k1)
    if method == "symplectic_euler":
        return symplectic_euler_step(f, n, dtype, with_k1, fq)
    if method == "verlet":
        return verlet_step(f, n, dtype, with_k1, fq)
    raise ValueError(f"method: unknown value {method!r}; allowed: {', '.join(METHODS)}")


def doubling_step(method: str, f: Callable, n: int, dtype, extrapolate: bool = False, fq=None):
    """Step doubling (Numerical Recipes §16.2) as one ``ti.func``: returns ``(y2, est)`` where y2 is
    two steps of h/2 (or its local extrapolation y2 + Δ/(2^p − 1), order p + 1) and
    ``est = Δ/(2^p − 1)`` with Δ = y2 − y1 estimates y2's local error. f(y, t) is evaluated once and
    shared by the full step and the first half step: Euler costs 2 evaluations, midpoint 5, RK4 11."""
    meth = METHODS[method]
    step = make_step(method, f, n, dtype, with_k1=True, fq=fq)
    denom = 2 ** meth.order - 1

    @ti.func
    def dstep(y, t, h, i):
        d1 = f(y, t, i)
        y1 = step(y, t, h, i, d1)
        half = h / 2
        ym = step(y, t, half, i, d1)
        y2 = step(ym, t + half, half, i, f(ym, t + half, i))
        est = (y2 - y1) / ti.cast(denom, dtype)
        if ti.static(extrapolate):
            y2 = y2 + est
        return y2, est

    return dstep


def doubling_fevals(method: str) -> int:
    """Derivative evaluations per step-doubling attempt (3 steps, one shared first evaluation)."""
    return 3 * METHODS[method].fevals - 1


@ti.func
def scaled_error(y, y_new, est, atol, rtol):
    """max_i |est_i| / (atol + rtol·max(|y_i|, |y_new_i|)) — the scipy/Hairer scaling, max norm.
    A non-finite estimate gives +inf, which the controller rejects."""
    r = ti.abs(est) / (atol + rtol * ti.max(ti.abs(y), ti.abs(y_new)))
    e = r.max()
    if not is_finite(r.sum()):  # the max of a vector may skip a NaN component; a sum cannot
        e = ti.math.inf
    return e


@ti.func
def is_finite(x):
    """True for a finite scalar. (x − x == 0 does not work: fast math folds it to true.)"""
    return not (ti.math.isnan(x) or ti.math.isinf(x))

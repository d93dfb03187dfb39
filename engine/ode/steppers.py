"""One-step methods as Taichi functions on one element's state, generated from the method data.

Every stepper here has the signature ``step(y, t, h, i) -> y_next`` where ``y`` is a
``ti.Vector`` of any length n, ``t`` and ``h`` are scalars of the state's dtype and ``i`` is an
opaque integer context (an element index in a batch) handed through to the derivative
``f(y, t, i) -> dy/dt``. The steppers know nothing else: not particles, not springs. They run
*fused*: every stage of one element in registers, which suits independent elements (particles,
small ODEs). Coupled elements (spring networks) run the same schemes staged over whole fields
(:mod:`engine.ode.staged`); both go through :func:`lincomb`, the one place a scheme's coefficients
meet the state.

* a :class:`~engine.ode.tableau.ButcherTableau` (euler, midpoint, rk4): stages unrolled with
  ``ti.static``, so a tableau costs exactly its stages and adding a method means adding data.
* a :class:`~engine.ode.splitting.Splitting` (symplectic_euler, verlet): kicks and drifts of the
  halves of y = (q, p); for particles q = (x, age), p = (v, 0), f = (v, 1, a(x, v, t), 0).
"""

from typing import Callable  # no __future__ annotations: Taichi reads them

import taichi as ti

from .methods import method as _method
from .splitting import KICK, Splitting


def coefficients(row):
    """Exact fractions as (numerator, denominator) pairs for :func:`lincomb`."""
    return tuple((q.numerator, q.denominator) for q in row)


@ti.func
def times(h, q: ti.template(), dtype: ti.template()):
    """h·q for an exact fraction q = (numerator, denominator), emitted as h·num/den in ``dtype``:
    exact for the rational schemes (h/6, not h times a rounded 1/6), and an f64 kernel never sees
    a constant rounded through Taichi's f32 default."""
    return h * ti.cast(q[0], dtype) / ti.cast(q[1], dtype)


@ti.func
def lincomb(y, h, coef: ti.template(), ks: ti.template(), dtype: ti.template()):
    """y + Σ_m (h·coef_m)·ks_m over the nonzero coefficients, unrolled at compile time."""
    out = y
    for m in ti.static(range(len(coef))):
        if ti.static(coef[m][0] != 0):
            out = out + times(h, coef[m], dtype) * ks[m]
    return out


def _with_first_eval(_step, f, with_k1: bool):
    """``_step(y, t, h, i, d1)`` takes f(y, t) precomputed (step doubling shares it between the
    full step and the first half step); the plain stepper evaluates it itself."""
    if with_k1:
        return _step

    @ti.func
    def step(y, t, h, i):
        return _step(y, t, h, i, f(y, t, i))

    return step


def rk_step(tab, f: Callable, dtype, with_k1: bool = False):
    """Explicit RK step for the tableau ``tab``: k_j = f(y + h Σ_m a_jm k_m, t + c_j h),
    y⁺ = y + h Σ_j b_j k_j."""
    s = tab.stages
    A = tuple(coefficients(row) for row in tab.a)
    C = coefficients(tab.c)
    B = coefficients(tab.b)

    @ti.func
    def _step(y, t, h, i, d1):
        ks = [d1] * s  # derivatives f(Y_j, t + c_j h), one per stage (a Python list, unrolled)
        for j in ti.static(range(1, s)):
            yj = lincomb(y, h, A[j], ks, dtype)
            ks[j] = f(yj, t + times(h, C[j], dtype), i)
        return lincomb(y, h, B, ks, dtype)

    return _with_first_eval(_step, f, with_k1)


def _half_masks(n: int):
    if n % 2:
        raise ValueError(f"partitioned methods need an even state length (q, p); got {n}")
    m = n // 2
    return [1] * m + [0] * m, [0] * m + [1] * m


def splitting_step(spl: Splitting, f: Callable, n: int, dtype, with_k1: bool = False, fq=None):
    """A kick–drift step on y = (q, p): the first half of y is q, the second p. A kick adds
    w·h·(p-part of f), a drift w·h·(q-part of f). The drift needs only the q-part, so a caller
    with a cheap ``fq`` (for particles: just v) passes it and the forces are evaluated only in
    the kicks."""
    mq, mp = _half_masks(n)
    fq = fq or f
    ops = tuple((kind, coefficients((w,)), coefficients((c,))[0]) for kind, w, c in spl.ops)

    @ti.func
    def _step(y, t, h, i, d1):
        Mq = ti.Vector(mq, dt=dtype)
        Mp = ti.Vector(mp, dt=dtype)
        for k in ti.static(range(len(ops))):
            tk = t + times(h, ops[k][2], dtype)
            if ti.static(ops[k][0] == KICK):
                d = d1
                if ti.static(k > 0):
                    d = f(y, tk, i)
                y = lincomb(y, h, ops[k][1], [Mp * d], dtype)
            else:
                y = lincomb(y, h, ops[k][1], [Mq * fq(y, tk, i)], dtype)
        return y

    return _with_first_eval(_step, f, with_k1)


def make_step(method: str, f: Callable, n: int, dtype, with_k1: bool = False, fq=None):
    """The ``ti.func`` stepper for ``method`` (a name of :data:`~engine.ode.methods.METHODS`) on
    states of length n. ``fq`` (partitioned methods only) evaluates just the q-part of f cheaply."""
    scheme = _method(method).scheme
    if isinstance(scheme, Splitting):
        return splitting_step(scheme, f, n, dtype, with_k1, fq)
    return rk_step(scheme, f, dtype, with_k1)


def doubling_step(method: str, f: Callable, n: int, dtype, extrapolate: bool = False, fq=None):
    """Step doubling (Numerical Recipes §16.2) as one ``ti.func``: returns ``(y2, est)`` where y2 is
    two steps of h/2 (or its local extrapolation y2 + Δ/(2^p − 1), order p + 1) and
    ``est = Δ/(2^p − 1)`` with Δ = y2 − y1 estimates y2's local error. f(y, t) is evaluated once and
    shared by the full step and the first half step: Euler costs 2 evaluations, midpoint 5, RK4 11."""
    meth = _method(method)
    step = make_step(method, f, n, dtype, with_k1=True, fq=fq)
    denom = 2 ** meth.order - 1

    @ti.func
    def dstep(y, t, h, i):
        # the full step, then the two halves, as one runtime loop around one inlined step: a
        # step inlined three times (RK4: 11 evaluations of f inlined, the forces' code each) was
        # most of a located adaptive kernel's compile (5.6 min cold for turbulence and two
        # colliders); looped, it is 4. The same operations on the same values in the same order,
        # but not always the same bits: under fast math LLVM rounds the loop's code otherwise
        # than the unrolled steps' (an adaptive scene's f32 error estimate moved by 1.5e-4).
        half = h / 2
        ya, ta, ha = y, t, h
        d = y
        y1, y2 = y, y
        for m in range(3):
            if m != 1:  # the first half step reuses the full step's f(y, t)
                d = f(ya, ta, i)
            yn = step(ya, ta, ha, i, d)
            if m == 0:
                y1, ha = yn, half
            elif m == 1:
                ya, ta = yn, t + half
            else:
                y2 = yn
        est = (y2 - y1) / ti.cast(denom, dtype)
        if ti.static(extrapolate):
            y2 = y2 + est
        return y2, est

    return dstep


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

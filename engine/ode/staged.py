"""The same schemes staged over whole fields: for coupled second-order systems (spring networks).

The state is two vector fields x, v of n elements with x' = v, v' = a(x, v) where a couples the
elements, so every stage needs all elements' stage states before any derivative: each stage is
one kernel over the elements and each derivative one call of the model's launcher
``accel(x, v, a, slot)`` writing a[slot, i]. The per-element arithmetic is
:func:`~engine.ode.steppers.lincomb` on the scheme's coefficients, as in the fused steppers:

* tableau: X_j = x + h Σ_m a_jm V_m, V_j = v + h Σ_m a_jm A_m, A_j = a(X_j, V_j) (V_0 = v);
  x⁺ = x + h Σ_j b_j V_j, v⁺ = v + h Σ_j b_j A_j.
* splitting: each kick and the drifts after it in one kernel; a kick after the first evaluates
  a at the state reached so far.

Step doubling (:class:`StagedDoubling`) shares a(x₀, v₀) between the full step and the first half
step, as the fused :func:`~engine.ode.steppers.doubling_step` does (RK4: 11 evaluations).
"""

import taichi as ti  # (no __future__ annotations: Taichi reads the kernels' annotations)

from .methods import method as _method
from .splitting import KICK, Splitting
from .steppers import coefficients, lincomb, scaled_error


@ti.func
def rk_stage_node(x: ti.template(), v: ti.template(), a: ti.template(), vs: ti.template(), yx: ti.template(),
                  yv: ti.template(), i, hh, coef: ti.template(), final: ti.template()):
    """Element i's (x, v) + h Σ_m coef_m (V_m, A_m) over the stages so far (m < len(coef),
    V_0 = v; hh = h in the fields' dtype): stage j = len(coef) into yx, yv and vs[j]; with
    ``final`` (coef = b) the step's result into x, v. Shared by the staged kernels and the soft
    bodies' fused frame (engine.springs.fused)."""
    j = ti.static(len(coef))
    kx, kv = [v[i]] * j, [a[0, i]] * j
    for m in ti.static(range(1, j)):
        kx[m], kv[m] = vs[m, i], a[m, i]
    xn = lincomb(x[i], hh, coef, kx, x.dtype)
    vn = lincomb(v[i], hh, coef, kv, x.dtype)
    if ti.static(final):
        x[i], v[i] = xn, vn
    else:
        yx[i], yv[i] = xn, vn
        vs[j, i] = vn


@ti.kernel
def _rk_lincomb(x: ti.template(), v: ti.template(), a: ti.template(), vs: ti.template(),
                yx: ti.template(), yv: ti.template(), n: ti.i32, h: ti.f64, coef: ti.template(),
                final: ti.template()):
    """:func:`rk_stage_node` over the n elements."""
    for i in range(n):
        rk_stage_node(x, v, a, vs, yx, yv, i, ti.cast(h, x.dtype), coef, final)


@ti.func
def kick_drift_node(x: ti.template(), v: ti.template(), a: ti.template(), i, hh, slot: ti.template(),
                    kick: ti.template(), drifts: ti.template()):
    """Node i's kick v += w·h·a[slot, i], then x += w_d·h·v for each drift weight in ``drifts``
    (the splitting's segment; hh = h in the fields' dtype): shared by the staged kernels and the
    soft bodies' fused frame (engine.springs.fused)."""
    vi = lincomb(v[i], hh, kick, [a[slot, i]], x.dtype)
    v[i] = vi
    xi = x[i]
    for d in ti.static(range(len(drifts))):
        xi = lincomb(xi, hh, drifts[d], [vi], x.dtype)
    x[i] = xi


@ti.kernel
def _kick_drifts(x: ti.template(), v: ti.template(), a: ti.template(), n: ti.i32, h: ti.f64,
                 slot: ti.template(), kick: ti.template(), drifts: ti.template()):
    """v += w·h·a[slot]; then x += w_d·h·v for each drift weight in ``drifts``."""
    for i in range(n):
        kick_drift_node(x, v, a, i, ti.cast(h, x.dtype), slot, kick, drifts)


class FieldStepper:
    """``step(h)`` advances the fields ``x``, ``v`` (n elements) by one step of ``method``.

    ``accel(x, v, a, slot)`` writes the accelerations of the state (x, v) into ``a[slot, :]``;
    the stepper owns ``a`` (shape (stages, N)) and the stage buffers. ``fevals`` counts
    evaluations per step."""

    def __init__(self, method: str, x, v, n: int, accel):
        meth = _method(method)
        self.method, self.order, self.fevals = meth.name, meth.order, meth.fevals
        self.x, self.v, self.n, self.accel = x, v, int(n), accel
        N, dtype = max(1, self.n), x.dtype
        scheme = meth.scheme
        if isinstance(scheme, Splitting):
            # one kernel per kick and the drifts after it; kick k reads the k-th evaluation
            self._segments, slot = [], -1
            for kind, w, _c in scheme.ops:
                if kind == KICK:
                    slot += 1
                    self._segments.append([slot, coefficients((w,)), ()])
                else:
                    self._segments[-1][2] += (coefficients((w,)),)
            slots = slot + 1
        else:
            self._rows = tuple(coefficients(row) for row in scheme.a)
            self._b = coefficients(scheme.b)
            slots = scheme.stages
            self.vs = ti.Vector.field(3, dtype, (slots, N))  # stage velocities (slot 0 unused: v)
            self.yx = ti.Vector.field(3, dtype, N)
            self.yv = ti.Vector.field(3, dtype, N)
        self.a = ti.Vector.field(3, dtype, (slots, N))  # one slot per evaluation

    def step(self, h: float, first_eval_done: bool = False) -> None:
        """One step of h. With ``first_eval_done`` a[0] already holds a(x, v) (step doubling)."""
        if self.n == 0:
            return
        x, v, a, n = self.x, self.v, self.a, self.n
        if not first_eval_done:
            self.accel(x, v, a, 0)
        if hasattr(self, "_segments"):
            for slot, kick, drifts in self._segments:
                if slot > 0:
                    self.accel(x, v, a, slot)
                _kick_drifts(x, v, a, n, h, slot, kick, tuple(drifts))
            return
        for j in range(1, len(self._rows)):
            _rk_lincomb(x, v, a, self.vs, self.yx, self.yv, n, h, self._rows[j], False)
            self.accel(self.yx, self.yv, a, j)
        _rk_lincomb(x, v, a, self.vs, self.yx, self.yv, n, h, self._b, True)


@ti.kernel
def copy_nodes(xs: ti.template(), vs: ti.template(), xd: ti.template(), vd: ti.template(), n: ti.i32):
    """(xd, vd)[:n] = (xs, vs)[:n]."""
    for i in range(n):
        xd[i] = xs[i]
        vd[i] = vs[i]


@ti.kernel
def _doubling_error(x0: ti.template(), v0: ti.template(), x1: ti.template(), v1: ti.template(),
                    x2: ti.template(), v2: ti.template(), err: ti.template(), n: ti.i32,
                    denom: ti.i32, atol: ti.f64, rtol: ti.f64, extrapolate: ti.template()) -> ti.f64:
    """max over elements of the scaled error of est = (y2 − y1)/(2^p − 1), y = (x, v) per element
    (a max is order-independent: deterministic under threads); with ``extrapolate`` y2 += est."""
    err[None] = 0
    for i in range(n):
        y0 = ti.Vector([x0[i][0], x0[i][1], x0[i][2], v0[i][0], v0[i][1], v0[i][2]])
        y1 = ti.Vector([x1[i][0], x1[i][1], x1[i][2], v1[i][0], v1[i][1], v1[i][2]])
        y2 = ti.Vector([x2[i][0], x2[i][1], x2[i][2], v2[i][0], v2[i][1], v2[i][2]])
        est = (y2 - y1) / ti.cast(denom, x0.dtype)
        ti.atomic_max(err[None], scaled_error(y0, y2, est, ti.cast(atol, x0.dtype), ti.cast(rtol, x0.dtype)))
        if ti.static(extrapolate):
            x2[i] += ti.Vector([est[0], est[1], est[2]])
            v2[i] += ti.Vector([est[3], est[4], est[5]])
    return err[None]


class StagedDoubling:
    """Step doubling over a :class:`FieldStepper`: ``attempt`` leaves the two-half-steps result
    in the stepper's fields and returns the scaled max-norm error; ``rollback`` restores the state
    the attempt started from. ``before(h, end)`` runs before each of the three steps (end = the
    fraction 1.0 or 0.5 of the attempted step at which that step ends): where a model drives some
    elements itself (a moving pin sets their velocity for the step)."""

    def __init__(self, stepper: FieldStepper, extrapolate: bool = False):
        self.stepper, self.extrapolate = stepper, bool(extrapolate)
        x = stepper.x
        N, dtype = max(1, stepper.n), x.dtype
        self.x0, self.v0 = ti.Vector.field(3, dtype, N), ti.Vector.field(3, dtype, N)
        self.x1, self.v1 = ti.Vector.field(3, dtype, N), ti.Vector.field(3, dtype, N)
        self.err = ti.field(ti.f64 if dtype == ti.f64 else ti.f32, ())
        self.fevals = 3 * stepper.fevals - 1

    def attempt(self, h: float, atol: float, rtol: float, before=None) -> float:
        st = self.stepper
        if st.n == 0:
            return 0.0
        before = before or (lambda h_, end: None)
        x, v, n = st.x, st.v, st.n
        copy_nodes(x, v, self.x0, self.v0, n)
        before(h, 1.0)
        st.accel(x, v, st.a, 0)  # a(y0), shared by the full step and the first half step
        st.step(h, first_eval_done=True)
        copy_nodes(x, v, self.x1, self.v1, n)
        copy_nodes(self.x0, self.v0, x, v, n)
        before(h / 2, 0.5)
        st.step(h / 2, first_eval_done=True)
        before(h / 2, 1.0)
        st.step(h / 2)
        return float(_doubling_error(self.x0, self.v0, self.x1, self.v1, x, v, self.err, n,
                                     2 ** st.order - 1, atol, rtol, self.extrapolate))

    def rollback(self) -> None:
        st = self.stepper
        if st.n:
            copy_nodes(self.x0, self.v0, st.x, st.v, st.n)

"""Event location inside a step: impacts found in time, for any of the core's steppers.

scipy's ``solve_ivp(events=...)`` finds where an event function changes sign within a step on the
step's dense output and stops there; here the element goes on: it is advanced to the event,
an *event set* responds (a collider reflects its velocity), and the step is finished from there
(NUMERICS.md, "Collisions"). :func:`located_step` wraps a stepper once, generically, and every
system uses it for its elements: each particle in the fused step kernels, each spring node after
its network's step, and :func:`engine.ode.solve`'s small state. Elements are located each on their
own: a pool's step is not cut once per contact.

The element's state is second order, y = (q, p) with q' = p (particles: (x, age | v, 0); spring
nodes (x, a | v, 0); solve's (x | v) with 3-D x), and events are functions of the point
x = q[0:3] moving at v = p[0:3]. Within one step from t to t + h:

1. take the step (or the rest of it) from y_a at t + s to y_b at t + h;
2. for each event function k with g_k(y_a) > 0 > g_k(y_b) (a crossing into the surface), find the
   root τ_k (a point that starts touching the surface, |g| within rounding, is looked for only
   when it moves away — a bounce that lands again within the step, bracketed from the top of its
   hop; one that stays is *held* by the event set's projection at the step's end, not located
   again: resting contact never stalls the stepper):
   closed form under constant acceleration where g is linear in x (a plane: the quadratic
   g₀ + ġ₀τ + ½ g̈τ² = 0 with g̈ = N·Δv/Δt), otherwise safeguarded Newton (bisection when a Newton
   step leaves the bracket) on the step's dense output, the cubic Hermite through (x, v) at both
   ends (O(h⁴) accurate), stopping when |g| ≤ ``tol_g`` or τ stops moving;
3. at the earliest root: advance to it with the stepper itself (so the state there has the
   method's own accuracy and error estimate), respond (the event set projects the point onto the
   surface and reflects its velocity), and go back to 1 for the rest of the step, at most
   :data:`MAX_EVENTS` times (a bouncing ball's Zeno tail falls to the projection).

A step that cannot meet any surface (``clear_of``: outside at its end and too short to reach one
from its start, the tests of 2 before any root is looked for) is the plain step and pays only
those tests (most particles, most steps).

The error the driver sees for a located step is the largest scaled error of its pieces, and the
distance the located point was off the surface (the dense output's error) beyond rounding, scaled
the same way: a step whose impact the Hermite cannot place within the tolerance is rejected and
retried shorter, so the tolerance bounds the bounce as it bounds the flight.

An event set (duck-typed; :class:`engine.colliders.Colliders` is one) has ``event_count`` (the
event functions, compile time; ``count`` ≥ it also counts shapes met by projection only) and ``dtype``,
``linear(k)`` and ``stops(k)`` (compile-time answers), ``contact(k, x, xd, lag) -> (g, ġ, N)``
(``lag``: seconds before the step's end: a moving surface is placed where it is then) and
``respond(k, x, v, lag, dv) -> (x', v', speed, N)`` and ``project(x, v, x0, v0, h) -> (x', v', hits,
killed, k, N, speed)`` (held contact at the step's end, :meth:`engine.colliders.Colliders.project`)
and ``near_projected(x) -> 1 | 0`` (whether x is near a shape met by projection only: such a
step is not clear, so the projection meets it); for the branch-free answers of
:mod:`engine.ode.lanes`, ``hold(k, x, v, dv, g, N) -> (x', v')`` (``project``'s response to shape k
alone, without branches).
"""
import taichi as ti  # (no __future__ annotations: Taichi reads the funcs' annotations)

from .steppers import is_finite, scaled_error

MAX_EVENTS = 4  # located impacts per element per step
EXHAUSTED = 1e3  # the error of a step that ends inside a surface after MAX_EVENTS impacts: retried shorter
NEWTON_ITERATIONS = 8  # per root; from the secant start a plane or a sphere needs 2–4
PASS_SAMPLES = 8  # a step outside at both ends that could pass through a surface: looked at every span/8
EPS_BAND = 16  # |g| within EPS_BAND × machine epsilon × (1 + |x|) of the surface: touching (rounding)


def _eps(dtype) -> float:
    return 2.0 ** -52 if dtype == ti.f64 else 2.0 ** -23


def contact_band(dtype):
    """``band(x)``: how close to a surface a point at x counts as touching it, m: EPS_BAND units
    of rounding of the point's coordinates (a point put on a surface lands within it)."""
    eps = _eps(dtype)

    @ti.func
    def band(x):
        return EPS_BAND * eps * (1.0 + ti.max(ti.abs(x[0]), ti.abs(x[1]), ti.abs(x[2])))

    return band


@ti.func
def hermite(x0, v0, x1, v1, h, s):
    """The cubic Hermite through (x0, v0) at 0 and (x1, v1) at h: its value and derivative at
    s ∈ [0, h] (Hairer, Nørsett & Wanner I, §II.6: error O(h⁴) for a smooth path)."""
    u = s / h
    w = 1.0 - u
    x = (1.0 + 2.0 * u) * w * w * x0 + u * w * w * h * v0 + u * u * (3.0 - 2.0 * u) * x1 - u * u * w * h * v1
    xd = 6.0 * u * w * (x1 - x0) / h + w * (1.0 - 3.0 * u) * v0 + u * (3.0 * u - 2.0) * v1
    return x, xd


def point_velocity(n: int):
    """Accessors of a second-order state of length n (q = y[:n/2], p = y[n/2:]): ``point(y)``,
    ``velocity(y)`` (3-vectors) and ``placed(y, x, v)`` (y with them replaced)."""
    if n % 2 or n < 6:
        raise ValueError(f"events need a second-order state (q, p) with 3-D points; got length {n}")
    m = n // 2

    @ti.func
    def point(y):
        return ti.Vector([y[0], y[1], y[2]])

    @ti.func
    def velocity(y):
        return ti.Vector([y[m], y[m + 1], y[m + 2]])

    @ti.func
    def placed(y, x, v):
        out = y
        for c in ti.static(range(3)):
            out[c] = x[c]
            out[m + c] = v[c]
        return out

    return point, velocity, placed


def clear_of(events, dtype):
    """``clear(xa, va, xb, vb, span) -> 1 | 0``: 1 when the step from (xa, va) to (xb, vb) over
    ``span`` cannot meet any surface of ``events``: for every contact, outside at the end and
    either touching at the start (held, not located) or too short to reach it,
    span·max(|va|, |vb|) ≤ g_a + g_b (the very tests :func:`located_step`'s crossing makes before
    it looks further). Then the located step is the plain step: no crossing is looked for, and
    the projection holds nothing."""
    band = contact_band(dtype)
    n_fn = events.event_count

    @ti.func
    def clear(xa, va, xb, vb, span):
        ok = 1
        reach2 = span * span * ti.max(va.norm_sqr(), vb.norm_sqr())
        for k in ti.static(range(n_fn)):
            ga, _gda, _Na = events.contact(k, xa, va, span)
            gb, _gdb, _Nb = events.contact(k, xb, vb, 0.0)
            # nested tests, the reach first: a far point (most points, most steps) does not
            # pay for the start's contact band
            if not (gb >= 0.0):
                ok = 0
            elif not (reach2 <= (ga + gb) * (ga + gb)):
                if not (ga <= band(xa)):
                    ok = 0
        if ti.static(events.event_count < events.count):
            if ok != 0 and events.near_projected(xb) != 0:
                ok = 0
        return ok

    return clear


def located_step(step, events, n: int, dtype, quadratic: bool = False, first_apart: bool = False):
    """``run(y, t, h, i, atol, rtol, tol_g) -> (y_end, err, count, k, lag, x, N, speed, dv, stopped)``:
    one step of ``step`` with the events of ``events`` located in it (module docstring).

    ``step(y, t, h, i, atol, rtol) -> (y_next, err)``: a step and its scaled error (0 for fixed
    steps). ``quadratic``: the acceleration is constant over a step (gravity only), so a linear
    contact's root is the closed form. Returns the state at t + h, the largest scaled error, how
    many events were located, and the fastest impact of the step: event function ``k`` (−1: none), ``lag`` (s before the step's
    end), the point ``x`` on the surface, the normal ``N``, the impact speed and the velocity change
    |Δv| (without a located impact, a contact held at the step's end by the event set's
    projection, with lag 0);
    ``stopped`` (1: an event function that ``stops`` was hit: y_end is the state at it).
    ``first_apart``: ``step`` gets a call site of its own for the whole step, before the loop
    over pieces (twice the inlined code; for a cheap ``step``, see ``run``)."""
    point, velocity, placed = point_velocity(n)
    eps = _eps(dtype)
    band = contact_band(dtype)
    n_fn = events.event_count  # event functions (compile time)

    @ti.func
    def root(k: ti.template(), xa, va, xb, vb, span, start, glo, gdlo, end, gend, N, tol_g):
        """Offset in [start, end] ⊆ [0, span] of the crossing of contact k on the path between
        (xa, va) at 0 and (xb, vb) at span, bracketed by g(start) = glo > 0 (ġ there gdlo) and
        g(end) = gend < 0."""
        lo = ti.cast(start, dtype)
        tau = ti.cast(-1.0, dtype)
        if ti.static(quadratic and events.linear(k)):
            gdd = N.dot(vb - va) / span  # g̈ = N·a (the collider moves linearly)
            disc = gdlo * gdlo - 2.0 * gdd * glo
            if disc >= 0.0:
                den = ti.sqrt(disc) - gdlo
                if den > 0.0:
                    tau = lo + 2.0 * glo / den  # the first root of g₀ + ġ₀τ + ½g̈τ² (no cancellation)
        if not (tau >= lo and tau <= end):
            hi = ti.cast(end, dtype)
            tau = lo + (hi - lo) * glo / (glo - gend)  # secant start inside the bracket
            it = 0
            while it < NEWTON_ITERATIONS:
                x, xd = hermite(xa, va, xb, vb, span, tau)
                g, gd, _N = events.contact(k, x, xd, span - tau)
                it += 1
                if g > 0.0:
                    lo = tau
                else:
                    hi = tau
                nxt = 0.5 * (lo + hi)
                if gd != 0.0:
                    newton = tau - g / gd
                    if newton > lo and newton < hi:
                        nxt = newton
                    if ti.abs(g / gd) <= 4.0 * eps * span:
                        nxt = tau  # Newton's step is below rounding: converged
                if ti.abs(g) <= tol_g or ti.abs(nxt - tau) <= 4.0 * eps * span:
                    it = NEWTON_ITERATIONS  # converged, or τ stopped moving
                tau = nxt
        return tau

    @ti.func
    def crossing(k: ti.template(), xa, va, xb, vb, span, tol_g):
        """Offset of the first crossing of contact k into its surface within [0, span], or −1.
        A point touching the surface at the start (within the rounding band) is held when it
        does not move away; moving away, it is looked for again where ġ's secant vanishes (the
        top of its hop): a bounce that lands again within the step. A point outside at both ends
        whose path is long enough to reach the surface is sampled at PASS_SAMPLES − 1 points: a
        long step through a sphere's cap is not missed because both its ends are outside (a
        graze shallower than the samples' spacing can be)."""
        tau = ti.cast(-1.0, dtype)
        ga, gda, N = events.contact(k, xa, va, span)
        gb, gdb, _Nb = events.contact(k, xb, vb, 0.0)
        # the bracket [lo, hi] with g(lo) > 0 > g(hi) (one root() call site: it is inlined)
        lo, glo, gdlo, hi, ghi = ti.cast(0.0, dtype), ga, gda, span, gb
        found = 0
        if gb < 0.0:
            if ga > band(xa):
                found = 1
            elif gda > 0.0 and gdb < 0.0:
                top = span * gda / (gda - gdb)
                x, xd = hermite(xa, va, xb, vb, span, top)
                gt, gdt, _Nt = events.contact(k, x, xd, span - top)
                if gt > band(x):
                    lo, glo, gdlo, found = top, gt, gdt, 1
        elif ga > band(xa) and span * span * ti.max(va.norm_sqr(), vb.norm_sqr()) > (ga + gb) * (ga + gb):
            # outside at both ends, but the path is long enough to reach the surface (g is
            # 1-Lipschitz in x; |v| is largest at an end of a constant-acceleration step)
            j = 1
            while j < PASS_SAMPLES:
                sj = span * j / PASS_SAMPLES
                x, xd = hermite(xa, va, xb, vb, span, sj)
                gj, gdj, _Nj = events.contact(k, x, xd, span - sj)
                if gj < 0.0:
                    hi, ghi, found = sj, gj, 1
                    j = PASS_SAMPLES
                else:
                    lo, glo, gdlo = sj, gj, gdj
                j += 1
        if found != 0:
            tau = root(k, xa, va, xb, vb, span, lo, glo, gdlo, hi, ghi, N, tol_g)
        return tau

    clear = clear_of(events, dtype)
    # two-way coupling (engine.particles.push): an event set with a ``pusher`` records, per
    # point i, the velocity change each response against a rigid body's shape gave; without
    # one the plain projection is compiled, as before
    pushes = getattr(events, "pusher", None) is not None

    @ti.func
    def pushed(k: ti.template(), i, x, dv, lag):
        if ti.static(pushes):
            events.push_event(k, i, x, dv, lag)

    if pushes:
        @ti.func
        def held(i, x, v, x0, v0, s):
            return events.project_for(x, v, x0, v0, s, i)
    else:
        @ti.func
        def held(i, x, v, x0, v0, s):
            return events.project(x, v, x0, v0, s)

    @ti.func
    def run(y, t, h, i, atol, rtol, tol_g):
        """The step, and only when it could meet a surface (:func:`clear`) the located one: a
        point far from every collider pays the plain step and a bound test."""
        # Each pass of the loop steps one piece, either to t + h (then looks for a crossing in
        # it) or to the event found in the previous pass (then responds and goes on with the
        # rest). The first pass is the whole step: when it is clear of every surface it is the
        # answer. ``step`` is inlined at each call site, the forces' code with it: by default it
        # has one, in the loop (with a second one for the first pass, a located step doubling
        # RK4 with turbulence and two colliders compiled in 22 s instead of 10). ``first_apart`` keeps
        # the whole step's call before the loop: twice the code, but the plain step (most
        # elements, most steps) runs outside the loop, faster (a fixed-step particle step with
        # located impacts ~15 % faster in the bench), and a caller that relies on its rounding
        # there keeps it (the spring nodes' ballistic path: the fused and launched soft-body
        # frames give the same bits so).
        zero = ti.Vector.zero(dtype, 3)
        s, length = ti.cast(0.0, dtype), ti.cast(h, dtype)
        ya, yb, err = y, y, ti.cast(0.0, dtype)
        first, acc = -1, zero  # the event the piece ends at (−1: it ends at t + h); a over the piece
        rec_k, rec_lag, rec_x, rec_n = -1, ti.cast(0.0, dtype), zero, zero
        rec_speed, rec_dv = ti.cast(-1.0, dtype), ti.cast(0.0, dtype)
        stopped, count, going, exhausted = 0, 0, 1, 0
        pieces, plain = 0, 0
        y1, e1 = y, ti.cast(0.0, dtype)
        if ti.static(first_apart):
            y1, e1 = step(y, t, h, i, atol, rtol)
            if clear(point(y), velocity(y), point(y1), velocity(y1), h) != 0:
                plain, going, yb, err = 1, 0, y1, ti.max(err, e1)
        while going != 0:
            e = ti.cast(0.0, dtype)
            if ti.static(first_apart):
                if pieces == 0:
                    yb, e = y1, e1
                else:
                    yb, e = step(ya, t + s, length, i, atol, rtol)
            else:
                yb, e = step(ya, t + s, length, i, atol, rtol)
            err = ti.max(err, e)
            if ti.static(not first_apart):
                if pieces == 0 and clear(point(y), velocity(y), point(yb), velocity(yb), h) != 0:
                    plain, going = 1, 0
            pieces += 1
            if plain != 0:
                pass
            elif first >= 0:  # advanced to the event: respond, then the rest of the step
                count += 1
                lag = h - s - length
                xe, ve = point(yb), velocity(yb)
                xr, vr = xe, ve
                for k in ti.static(range(n_fn)):
                    if k == first:
                        miss, _gd, Ne = events.contact(k, xe, ve, lag)
                        off = ti.max(ti.abs(miss) - band(xe), 0.0)
                        err = ti.max(err, off / (atol + rtol * xe.norm()))
                        # rest (the Zeno tail's end): a rebound whose hop would rise less than
                        # tol_g under the piece's mean acceleration a is not bounced: the event
                        # set rests when e|v_n| ≤ −N·dv, with dv = a·t_rest, t_rest = √(2 tol_g/|N·a|)
                        a_n = Ne.dot(acc)
                        dv_rest = zero
                        if a_n < 0.0:
                            dv_rest = acc * ti.sqrt(2.0 * tol_g / -a_n)
                        xr, vr, speed, N = events.respond(k, xe, ve, lag, dv_rest)
                        pushed(k, i, xr, vr - ve, lag)
                        if speed > rec_speed:
                            rec_k, rec_lag, rec_x, rec_n = k, lag, xr, N
                            rec_speed, rec_dv = speed, (vr - ve).norm()
                        if ti.static(events.stops(k)):
                            stopped = 1
                ya = placed(yb, xr, vr)
                s += length
                length = h - s
                first = -1
                if stopped != 0 or length <= 0.0:
                    yb = ya
                    going = 0
            else:  # the piece ends at t + h: the earliest crossing in it, if any
                going = 0
                if count >= MAX_EVENTS:
                    exhausted = 1
                else:
                    xa, va, xb, vb = point(ya), velocity(ya), point(yb), velocity(yb)
                    best = length
                    if length > 0.0 and is_finite(xb.sum() + vb.sum()):
                        for k in ti.static(range(n_fn)):
                            tau = crossing(k, xa, va, xb, vb, length, tol_g)
                            if tau >= 0.0 and (tau < best or first < 0):
                                first, best = k, tau
                    if first >= 0:
                        acc = (vb - va) / length
                        length = best
                        going = 1
        if exhausted != 0:  # MAX_EVENTS located and the rest of the step not looked at:
            xb = point(yb)  # ending inside a surface, it is retried shorter (adaptive steps)
            for k in ti.static(range(n_fn)):
                gb, _gdb, _Nb = events.contact(k, xb, velocity(yb), 0.0)
                if gb < -band(xb):
                    err = ti.max(err, EXHAUSTED)
        if stopped == 0 and plain == 0:  # contact held: the event set's projection from the last piece's start
            # (a point that rested at its last event and sank back in under gravity is held
            # there, not bounced with the speed it gained inside)
            xp, vp, hits, kill, which, nrm, spd = held(i, point(yb), velocity(yb), point(ya), velocity(ya), h - s)
            if hits > 0:
                if rec_k < 0:  # a held contact is reported (at the step's end) when none was located
                    rec_k, rec_lag, rec_x, rec_n = which, ti.cast(0.0, dtype), xp, nrm
                    rec_speed, rec_dv = spd, (vp - velocity(yb)).norm()
                yb = placed(yb, xp, vp)
                stopped = kill
        return yb, err, count, rec_k, rec_lag, rec_x, rec_n, ti.max(rec_speed, 0.0), rec_dv, stopped

    return run


def fixed_error(step, dtype):
    """A fixed stepper ``step(y, t, h, i)`` in :func:`located_step`'s form (its error is 0)."""

    @ti.func
    def stepped(y, t, h, i, atol, rtol):
        return step(y, t, h, i), ti.cast(0.0, dtype)

    return stepped


def doubling_error(dstep):
    """A step-doubling stepper ``dstep(y, t, h, i) -> (y2, est)`` in :func:`located_step`'s form:
    its scaled max-norm error (:func:`~engine.ode.steppers.scaled_error`)."""

    @ti.func
    def stepped(y, t, h, i, atol, rtol):
        y2, est = dstep(y, t, h, i)
        return y2, scaled_error(y, y2, est, atol, rtol)

    return stepped

"""The located step's answers without branches, for elements stepped side by side.

A pool stepped several elements at a time (the particles' blocks: engine.particles.integrate)
keeps the compiler's vector instructions only as long as no element branches. These functions
give, for an event set (:mod:`engine.ode.events`), the answer :func:`~engine.ode.events.located_step`
would give where that is cheap to know without locating anything: every contact's tests
evaluated, the answers combined bitwise. An element they do not settle takes the located step
itself, so the two together take the located step's answers everywhere (to rounding).
"""
import taichi as ti  # (no __future__ annotations: Taichi reads the funcs' annotations)

from .events import contact_band


def far_from(events, dtype):
    """``far(xb, va, vb, span) -> 1 | 0``: 1 when the step that ends at xb, from velocity va to vb
    over ``span``, ends outside every surface of ``events`` by more than it could travel,
    span·max(|va|, |vb|) ≤ g_b. That implies :func:`~engine.ode.events.clear_of`'s answer (g_a ≥ 0 gives
    reach ≤ g_a + g_b; g_a < 0 lies within the contact band), so a caller that takes the plain
    step where ``far`` says 1 and asks ``clear`` elsewhere takes the same steps. (Asked first
    inside ``clear`` itself it saved ~9 % of the slot-at-a-time step, but its start's contact,
    no longer shared with the located path's, rounded differently there: sparks.toml's frames
    moved.) Without branches — every contact's test evaluated, the answers ANDed —
    so the same code for neighbouring elements becomes vector instructions (the particles'
    blocks, engine.particles.integrate, which ask :func:`settled` where it says 0); for an event
    set with no shapes met by projection only."""
    if events.event_count < events.count:
        raise ValueError("far_from: the event set has shapes met by projection only; use clear_of")
    n_fn = events.event_count

    @ti.func
    def far(xb, va, vb, span):
        reach2 = span * span * ti.max(va.norm_sqr(), vb.norm_sqr())
        ok = 1
        for k in ti.static(range(n_fn)):
            gb, _gdb, _Nb = events.contact(k, xb, vb, 0.0)
            ok &= ti.cast(gb >= 0.0, ti.i32) & ti.cast(reach2 <= gb * gb, ti.i32)
        return ok

    return far


def settled(events, dtype, hold: bool = True):
    """``settle(xa, va, xb, vb, span) -> (ok, x, v, held)``, without branches: ok = 1 where
    :func:`~engine.ode.events.located_step`, given the plain step from (xa, va) to (xb, vb) over ``span``, would
    locate no impact, and then (x, v) is what it returns: (xb, vb), or with ``held`` = 1 where
    one plane holds the point at the step's end (its projection, ``events.hold``). Every
    contact's tests are evaluated and the answers combined bitwise, so the same code for
    neighbouring elements becomes vector instructions (the particles' blocks,
    engine.particles.integrate); ok = 0 sends an element to the located step itself, so a
    caller that takes (x, v) where ok = 1 and the located step elsewhere takes the located
    step's answers everywhere (to rounding). For an event set with no shapes met by projection
    only. Contact k lets the step through (``passes``) when the point ends outside it and:

    1. it started touching it (within the contact band: held, not located), or
    2. the step is too short to reach it, span·max(|va|, |vb|) ≤ g_a + g_b — 1 and 2 are
       :func:`~engine.ode.events.clear_of`'s tests, which are the crossing's own before it looks further; or
    3. (a linear contact: a plane that does not spin) the crossing's samples cannot find it:
       g along the step's dense output is then the cubic Hermite through (g_a, ġ_a) and
       (g_b, ġ_b), which lies above its Bernstein coefficients' minimum, min(g_a + span·ġ_a/3,
       g_b − span·ġ_b/3) (with g_a, g_b: Farin, *Curves and Surfaces for CAGD*, the convex
       hull property), asked to exceed both ends' contact bands so the samples' rounding cannot
       reach below 0. A point skimming a plane (most of a bench's particles near the ground
       between bounces) passes so, where 2 sent it to the samples.

    A plane k that is not ``stops(k)`` *holds* the point when it started touching it, is not
    moving away there (ġ_a ≤ 0: the crossing looks for no bounce) and ends inside it, while every
    other contact passes and, for those after k in the table, the held point ends outside them
    too (the projection meets the shapes in table order): the located step finds no crossing and
    its projection responds to k alone. ``hold`` False: no contact holds (a caller that must
    record every contact takes the located step there)."""
    if events.event_count < events.count:
        raise ValueError("settled: the event set has shapes met by projection only; use clear_of")
    band = contact_band(dtype)
    n_fn = events.event_count
    holds = [k for k in range(n_fn) if hold and events.linear(k) and not events.stops(k)]

    @ti.func
    def passes(k: ti.template(), xa, va, xb, vb, span, reach2):
        ga, gda, _Na = events.contact(k, xa, va, span)
        gb, gdb, _Nb = events.contact(k, xb, vb, 0.0)
        ok = ti.cast(ga <= band(xa), ti.i32) | ti.cast(reach2 <= (ga + gb) * (ga + gb), ti.i32)
        if ti.static(events.linear(k)):
            lo = ti.min(ga + span * gda / 3.0, gb - span * gdb / 3.0, ga, gb)
            ok |= ti.cast(lo > band(xa) + band(xb), ti.i32)
        return ti.cast(gb >= 0.0, ti.i32) & ok

    @ti.func
    def settle(xa, va, xb, vb, span):
        reach2 = span * span * ti.max(va.norm_sqr(), vb.norm_sqr())
        through = ti.Vector.zero(ti.i32, n_fn)
        for k in ti.static(range(n_fn)):
            through[k] = passes(k, xa, va, xb, vb, span, reach2)
        ok = 1
        for k in ti.static(range(n_fn)):
            ok &= through[k]
        x, v, held = xb, vb, 0
        for k in ti.static(holds):
            ga, gda, _Na = events.contact(k, xa, va, span)
            gb, _gdb, Nb = events.contact(k, xb, vb, 0.0)
            xk, vk = events.hold(k, xb, vb, vb - va, gb, Nb)
            on = ti.cast(gb < 0.0, ti.i32) & ti.cast(ga <= band(xa), ti.i32) & ti.cast(gda <= 0.0, ti.i32)
            for m in ti.static(range(n_fn)):
                if ti.static(m < k):
                    on &= through[m]
                elif ti.static(m > k):
                    gm, _gdm, _Nm = events.contact(m, xk, vk, 0.0)
                    on &= through[m] & ti.cast(gm >= 0.0, ti.i32)
            x = ti.select(on != 0, xk, x)
            v = ti.select(on != 0, vk, v)
            held |= on
        return ok | held, x, v, held

    return settle

"""Particle stepping: the ODE core's steppers fused into one kernel per step.

Each particle's state is y = (x, age, v, 0) ∈ R⁸ with y' = (v, 1, a(x, v, age, t), 0); the
particles do not interact, so all stages of a method run in registers inside one parallel loop
(PERF-NOTES: one fused RK4 kernel is ~3× faster than stage kernels). Impacts are located inside
the step in the same kernel (the ODE core's :func:`~engine.ode.events.located_step`: each
particle advanced to its impact time, reflected, finished), then contacts are held and the
particle aged (:meth:`ParticleIntegrator.finish`). With step doubling,
``attempt`` writes a candidate and returns the max-norm error over live particles (a max is
order-independent, so the result does not depend on threads); ``commit`` accepts it.

The kernels are module-level over the :class:`ParticleIntegrator` (a template argument: its
stepper, forces and colliders are compile-time parts of it), warp.sim style; the particle system
(:mod:`.system`) launches them.
"""
import taichi as ti

from ..contacts import ContactBuffer
from ..launch import data_oriented, fast
from ..geometry.shapes import PLANE, SPHERE
from ..ode.events import doubling_error, fixed_error, located_step
from ..ode.lanes import far_from, settled
from ..ode.steppers import doubling_step, is_finite, make_step, scaled_error
from .pool import LANES, lanes_of

NO_FAILURE = 1e30  # sentinel in nonfinite_t: no particle went non-finite (f32 inf does not survive a field write)


@ti.func
def _pack(x, age, v):
    """The ODE state of one particle: q = (x, age), p = (v, 0) — age is integrated (age' = 1)
    so age-dependent forces (buoyancy cooling) see the age at each stage, not the step's start."""
    return ti.Vector([x[0], x[1], x[2], age, v[0], v[1], v[2], 0.0])


@ti.func
def _x(y):
    return ti.Vector([y[0], y[1], y[2]])


@ti.func
def _v(y):
    return ti.Vector([y[4], y[5], y[6]])


def particle_derivative(accel):
    """(f, f_q) for the ODE core's steppers: f(y, t, i) = (v, 1, a(x, v, age, t), 0) with the
    scene's acceleration ``accel(x, v, age, t, i)``; f_q(y, t, i) = (v, 1, 0, 0), all the drift of a
    kick–drift method needs (the forces are evaluated in the kicks only)."""

    @ti.func
    def deriv(y, t, i):
        v = _v(y)
        return _pack(v, 1.0, accel(_x(y), v, y[3], t, i))

    @ti.func
    def deriv_q(y, t, i):
        return _pack(_v(y), 1.0, ti.Vector([0.0, 0.0, 0.0]))

    return deriv, deriv_q



@data_oriented
class ParticleIntegrator:
    """The compiled parts of a scene's particle step and what the step reports.

    ``colliders``: the scene's :class:`~engine.colliders.Colliders` (None: none). ``impacts``:
    "located" (each particle's impacts found in time inside the step by the ODE core's
    :func:`~engine.ode.events.located_step`, then the step is finished from there) or "projected"
    (a point that ends a step inside a collider is put back on the surface and reflected: first
    order in h, the cheapest). Both hold contact at rest with the colliders' projection.
    ``quadratic``: the acceleration is constant over a step (gravity only): a plane's impact time
    is a closed form. With ``contacts`` > 0 up to that many contacts between drains are recorded in
    ``contact_log`` (an engine.contacts.ContactBuffer) (slot, collider, position, normal, impact speed, time: the located time
    and position of the step's fastest impact); without, the unused outputs are dead code. With
    ``events`` each step records in ``particle_event`` who died (bit 1) or hit a collider (bit 2,
    |Δv| in ``particle_impact``, where and how long before the step's end in
    ``particle_impact_pos``/``particle_impact_lag``) for the sub-emitters, after clearing the
    previous step's. With step doubling the step's fastest impact waits in ``cand_hit*`` fields
    until the step is committed."""

    def __init__(self, state, accel, colliders, method: str, adaptive: bool, extrapolate=False,
                 events: bool = False, contacts: int = 0, impacts: str = "located", quadratic: bool = False,
                 lanes: bool = True):
        self.state, self.cap = state, state.capacity
        self.nonfinite_t = ti.field(ti.f32, shape=())
        self.err = ti.field(ti.f32, shape=())
        self.hits = ti.field(ti.i32, shape=())  # particle-steps with a contact (one record each)
        self.nonfinite_t[None] = NO_FAILURE
        self.has_colliders = colliders is not None and colliders.count > 0
        self.adaptive = bool(adaptive)
        self.colliders = colliders
        self.located = self.has_colliders and impacts == "located"
        # Located impacts against boxes and capsules (rigid bodies' shapes) make the step kernels
        # long: compiled without Taichi's whole-kernel CSE, whose cost grows with the square of a
        # kernel's size (debris' step_fixed: 83 -> 26 s cold; engine.runtime.without_kernel_cse).
        # Planes and spheres keep it: the 4M bench step ran ~10 % faster with it (2026-11-28).
        self.lean = self.located and any(s.kind in ("box", "capsule") for s in colliders.specs)
        self.events = bool(events)
        self.record = bool(contacts) and self.has_colliders
        # the records the API drains (engine.contacts: slot, collider, located position and time)
        self.contact_log = ContactBuffer(int(contacts) if self.record else 0)
        deriv, deriv_q = particle_derivative(accel)
        self.step = make_step(method, deriv, 8, ti.f32, fq=deriv_q)
        self.dstep = doubling_step(method, deriv, 8, ti.f32, extrapolate, fq=deriv_q) if adaptive else None
        if self.located:
            stepper = doubling_error(self.dstep) if adaptive else fixed_error(self.step, ti.f32)
            # a fixed step keeps its whole step's own call site (the plain step outside the
            # loop over pieces runs faster: the bench's located step x1.24 of the projected
            # one, x1.43 with one site); step doubling's is three steps, so it takes one site
            # (a located adaptive RK4 kernel compiled in 10 s instead of 22)
            self.locate = located_step(stepper, colliders, 8, ti.f32, quadratic, first_apart=not adaptive)
        # A fixed step without sub-emitters' events takes the pool's blocks of LANES slots side by
        # side (step_fixed, _step_lanes) with no colliders, or with located impacts against
        # planes and spheres that do not spin (their contact has no branches: engine.ode.lanes); projected impacts, step doubling and other shapes take a slot at a time, and
        # so does a scene whose caller says ``lanes`` False: the lanes inline the acceleration
        # LANES times more, and curl-noise turbulence made that costly to compile (smoke.toml's
        # first run, no cache: symplectic Euler 5.3 -> 11.0 s, midpoint 6.0 -> 17.9, RK4
        # 10.9 -> 69.7; sparks 3.2-3.8 -> 5.2-6.2). Compiled without Taichi's whole-kernel CSE
        # the lanes were not vectorised (the bench's step as slow as slot by slot): no way out.
        self.lanes = bool(lanes) and state.blocked and not self.adaptive and not self.events and (
            not self.has_colliders or self.located and colliders.event_count == colliders.count
            and all(kd in (PLANE, SPHERE) and not sp for kd, sp in zip(colliders.kinds, colliders.spins)))
        if self.lanes and self.has_colliders:
            self.far = far_from(colliders, ti.f32)
            # a plane's held contact settled in the lanes too, unless every contact is recorded
            self.settle = settled(colliders, ti.f32, hold=not self.record)
        self.blocks = lanes_of(self.cap) // LANES
        if adaptive and self.located:
            n = max(1, self.cap)
            self.cand_hit = ti.field(ti.i32, shape=n)  # collider + 1 (0: none), negative: it stopped the particle
            if self.record or self.events:
                self.cand_hit_lag, self.cand_hit_speed = ti.field(ti.f32, shape=n), ti.field(ti.f32, shape=n)
                self.cand_hit_dv = ti.field(ti.f32, shape=n)
                self.cand_hit_pos = ti.Vector.field(3, ti.f32, shape=n)
                self.cand_hit_n = ti.Vector.field(3, ti.f32, shape=n)

    @ti.func
    def advance(self, y0, t, h, i, atol: ti.f32, rtol: ti.f32, tol_g: ti.f32):
        """One step of y0 from t by h (fixed or step doubling): (y, err, impact...) as
        :func:`~engine.ode.events.located_step` returns them; without located impacts, none."""
        zero = ti.Vector([0.0, 0.0, 0.0])
        y, err = y0, 0.0
        k, lag, xh, nh, speed, dv, stopped = -1, 0.0, zero, zero, 0.0, 0.0, 0
        if ti.static(self.located):
            y, err, _count, k, lag, xh, nh, speed, dv, stopped = self.locate(y0, t, h, i, atol, rtol, tol_g)
        elif ti.static(self.adaptive):
            y2, est = self.dstep(y0, t, h, i)
            y, err = y2, scaled_error(y0, y2, est, atol, rtol)
        else:
            y = self.step(y0, t, h, i)
        return y, err, k, lag, xh, nh, speed, dv, stopped

    @ti.func
    def finish(self, i, x0, v0, x_end, v_end, t_end, h, k_hit, lag_hit, x_hit, n_hit, s_hit, dv_hit, stopped):
        """Accept particle i's step ending at t_end: hold contacts (the colliders' projection),
        record the step's fastest impact (the located one, or a projection's), age and retire.
        With two-way coupling the projection records slot i's pushes on rigid bodies
        (engine.particles.push; the located step records its own)."""
        S = self.state
        x, v, k, lag, xh, nh, speed, dv = x_end, v_end, k_hit, lag_hit, x_hit, n_hit, s_hit, dv_hit
        if is_finite(x.sum() + v.sum()):
            killed = stopped
            if ti.static(self.has_colliders):
                if ti.static(not self.located):  # (located_step holds contacts itself)
                    nx, nv, n_in, kill_in, which, nrm, spd = self.colliders.project_for(x, v, x0, v0, h, i)
                    if n_in > 0:
                        if k < 0 or spd > speed:
                            k, lag, xh, nh, speed, dv = which, 0.0, nx, nrm, spd, (nv - v).norm()
                    x, v, killed = nx, nv, kill_in
                if k >= 0:  # one contact per particle and step: its fastest (records = hits)
                    ti.atomic_add(self.hits[None], 1)
                    if ti.static(self.record):
                        # any thread order: the drain sorts by (time, slot)
                        self.contact_log.record(i, k, xh, nh, speed, t_end - lag, S.particle_emitter[i])
                    if ti.static(self.events):
                        S.particle_event[i] |= 2
                        S.particle_impact[i] = dv
                        S.particle_impact_pos[i] = xh
                        S.particle_impact_lag[i] = lag
            S.particle_pos[i] = x
            S.particle_vel[i] = v
            a = S.particle_age[i] + h
            S.particle_age[i] = a
            if a >= S.particle_life[i] or killed != 0:
                S.particle_alive[i] = 0
                if ti.static(self.events):
                    S.particle_event[i] |= 1
        else:
            ti.atomic_min(self.nonfinite_t[None], t_end)
            S.particle_alive[i] = 0

    @ti.func
    def clear_event(self, i):
        if ti.static(self.events):
            self.state.particle_event[i] = 0
            self.state.particle_impact[i] = 0.0


@ti.func
def _step_one(I: ti.template(), i, t: ti.template(), h: ti.template()):
    """One step of h from t for particle i if it is live; a particle born a0 = −age seconds into
    the step is integrated from its birth (and waits, ageing, when it is born after the step)."""
    S = I.state
    I.clear_event(i)
    if S.particle_alive[i] != 0:
        a0 = ti.min(S.particle_age[i], 0.0)  # < 0: born a0 seconds into this step
        if -a0 < h:
            x0, v0 = S.particle_pos[i], S.particle_vel[i]
            y0 = _pack(x0, ti.max(S.particle_age[i], 0.0), v0)
            y, _err, k, lag, xh, nh, speed, dv, stopped = I.advance(y0, t - a0, h + a0, i, 1.0, 1.0, 0.0)
            I.finish(i, x0, v0, _x(y), _v(y), t + h, h, k, lag, xh, nh, speed, dv, stopped)
        else:
            S.particle_age[i] += h  # not born yet


@ti.func
def _step_lanes(I: ti.template(), b, t: ti.template(), h: ti.template()):
    """:func:`_step_one` for the LANES slots of block b side by side, as far as the plain step
    goes: each live slot's step from its birth, written where it ends finite and (with colliders)
    meets no surface, or rests on a plane that holds it there (engine.ode.lanes.settled: the
    located step's answer where it locates no impact). Returns the mask of the block's other
    live slots (bit j: slot LANES·b + j; a step with an impact to locate, a birth after the
    step, a non-finite end), which then take :func:`_step_one`, and how many slots a plane held
    here. Each slot's arithmetic is the slot-at-a-time step's, its last bits rounded as the
    compiler's vector code has it (fast math reassociates: tests/test_step_lanes.py bounds the
    difference); the same bytes for any thread count, and a slot's path depends on its own state
    only.

    Without a branch until that mask, over neighbouring memory (engine.particles.pool), the
    compiler makes one vector instruction of the lanes' four (the bench's 4M located step with
    a ground plane 18.9/22.8 -> 11.7/12.3 ms, without colliders 7.7/9.7 -> 4.8/5.1, alternating
    processes, 2026-12-02),
    provided the slow slots' step is not inlined here: it is taken after, from one call site
    (four call sites here ran at the old speed; so did Python's ``and``, which branches)."""
    S = I.state
    # every lane's step, then every lane's stores (rows: lanes; static indices keep them in
    # registers)
    X0, V0 = ti.Matrix.zero(ti.f32, LANES, 3), ti.Matrix.zero(ti.f32, LANES, 3)
    X1, V1 = ti.Matrix.zero(ti.f32, LANES, 3), ti.Matrix.zero(ti.f32, LANES, 3)
    age, ok, alive = ti.Vector.zero(ti.f32, LANES), ti.Vector.zero(ti.i32, LANES), ti.Vector.zero(ti.i32, LANES)
    held, near = ti.Vector.zero(ti.i32, LANES), ti.Vector.zero(ti.i32, LANES)
    for j in ti.static(range(LANES)):
        i = b * LANES + j
        x0, v0 = S.particle_pos[i], S.particle_vel[i]
        age[j], alive[j] = S.particle_age[i], S.particle_alive[i]
        a0 = ti.min(age[j], 0.0)  # < 0: born a0 seconds into this step
        y1 = I.step(_pack(x0, ti.max(age[j], 0.0), v0), t - a0, h + a0, i)
        x1, v1 = _x(y1), _v(y1)
        # (bitwise: `and` would branch, and a branch ends the compiler's run of vectorisable code)
        ok[j] = ti.cast(alive[j] != 0, ti.i32) & ti.cast(-a0 < h, ti.i32) & ti.cast(is_finite(x1.sum() + v1.sum()), ti.i32)
        if ti.static(I.has_colliders):
            far = I.far(x1, v0, v1, h + a0)
            near[j] = ok[j] & (1 - far)
            ok[j] &= far
        for c in ti.static(range(3)):
            X0[j, c], V0[j, c], X1[j, c], V1[j, c] = x0[c], v0[c], x1[c], v1[c]
    if ti.static(I.has_colliders):
        # a block with a slot near a surface asks the located step's answer for its slots, still
        # without branches; the others pay the bound test only (asked of every block, the
        # settling made the bench's 4M step slower where few particles had landed yet). A slot
        # at rest on a plane or skimming it stays in the lanes: the bench's 4M located step
        # after 200 steps (~7 % of the particles on the ground) 34.0 -> 23.6 ms, after 34 steps
        # 13.7-15.7 -> 13.0-14.8 ms; at 1M after 34 steps equal (2.74 / 2.80), in one process
        # on an Intel Xeon, 2026-12-02
        anywhere = 0  # (ORed, one vector test: the sum was a chain of scalar adds)
        for j in ti.static(range(LANES)):
            anywhere |= near[j]
        if anywhere != 0:
            for j in ti.static(range(LANES)):
                x0 = ti.Vector([X0[j, 0], X0[j, 1], X0[j, 2]])
                v0 = ti.Vector([V0[j, 0], V0[j, 1], V0[j, 2]])
                x1 = ti.Vector([X1[j, 0], X1[j, 1], X1[j, 2]])
                v1 = ti.Vector([V1[j, 0], V1[j, 1], V1[j, 2]])
                clear, xs, vs, on = I.settle(x0, v0, x1, v1, h + ti.min(age[j], 0.0))
                take = near[j] & clear
                ok[j] |= take
                held[j] = take & on
                for c in ti.static(range(3)):
                    X1[j, c], V1[j, c] = xs[c], vs[c]
    slow = 0
    # every lane's end stored, then the lanes not taken here (slow; dead in a block with live
    # slots) put back as they were, the same bytes as a select per value, which the compiler
    # stored one float at a time (`particles bench --only step`, alternating processes, the fused
    # kernel at 4M 18.3/19.0 -> 15.5/16.7 ms, at 1M 3.47/3.89 -> 3.26/3.27; a hand-written step on
    # this layout went from 61-64 % of the bandwidth limit to 74-75 % so, 2026-12-03)
    for j in ti.static(range(LANES)):
        S.particle_pos[b * LANES + j] = ti.Vector([X1[j, 0], X1[j, 1], X1[j, 2]])
    for j in ti.static(range(LANES)):
        S.particle_vel[b * LANES + j] = ti.Vector([V1[j, 0], V1[j, 1], V1[j, 2]])
    every = 1
    for j in ti.static(range(LANES)):
        i = b * LANES + j
        a = age[j] + h
        S.particle_age[i] = a
        S.particle_alive[i] = ti.select((ok[j] & ti.cast(a >= S.particle_life[i], ti.i32)) != 0, 0, alive[j])
        every &= ok[j]
    if every == 0:
        # the masks built only here, where a lane is not taken: built for every block, lane by
        # lane from the vector compare (extract, shift, or), they were about a third of the
        # block's instructions (`particles bench --only step`, one run each on an Intel Xeon,
        # 2026-12-04: the fused kernel at 1M 2.16 -> 1.59 ms, at 4M 8.86 -> 6.96, the same bytes;
        # with `near` ORed, not summed, below)
        kept = 0
        for j in ti.static(range(LANES)):
            slow |= (ti.cast(alive[j] != 0, ti.i32) & (1 - ok[j])) << j
            kept |= (1 - ok[j]) << j
        for j in ti.static(range(LANES)):
            if (kept >> j) & 1 != 0:
                S.particle_pos[b * LANES + j] = ti.Vector([X0[j, 0], X0[j, 1], X0[j, 2]])
                S.particle_vel[b * LANES + j] = ti.Vector([V0[j, 0], V0[j, 1], V0[j, 2]])
                S.particle_age[b * LANES + j] = age[j]
    return slow, held.sum()


@ti.func
def _step_block(I: ti.template(), b, t: ti.template(), h: ti.template()):
    """Block b's slots stepped (:func:`_step_lanes`, then its slow slots one at a time)."""
    live = 0
    for j in ti.static(range(LANES)):
        live |= I.state.particle_alive[b * LANES + j]
    if live != 0:  # (a block of dead slots changes nothing)
        slow, held = _step_lanes(I, b, t, h)
        if held != 0:  # particle-steps in contact (finish counts the slow slots')
            ti.atomic_add(I.hits[None], held)
        if slow != 0:
            for q in range(LANES):
                if (slow >> q) & 1 != 0:
                    _step_one(I, b * LANES + q, t, h)


@ti.kernel
def step_fixed(I: ti.template(), t: ti.f32, h: ti.f32):
    """One step of h from t for every particle."""
    if ti.static(I.lanes):
        for b in range(I.blocks):
            _step_block(I, b, t, h)
    else:
        for i in range(I.cap):
            _step_one(I, i, t, h)


@ti.kernel
def step_fixed_run(I: ti.template(), t0: ti.f64, h: ti.f64, j: ti.i32, k: ti.i32):
    """Steps j … j + k − 1 of h from t0 in one launch, each particle (each block of them) taking
    them one after the other: for a run of steps with nothing to do in between (no births due,
    colliders still, no sub-emitters). Step m starts at t0 + m·h, rounded to f32 from f64 as a
    launch of :func:`step_fixed` with that start would be: the same bytes as k launches."""
    if ti.static(I.lanes):
        for b in range(I.blocks):
            for m in range(j, j + k):
                _step_block(I, b, ti.cast(t0 + m * h, ti.f32), ti.cast(h, ti.f32))
    else:
        for i in range(I.cap):
            for m in range(j, j + k):
                _step_one(I, i, ti.cast(t0 + m * h, ti.f32), ti.cast(h, ti.f32))


@ti.kernel
def attempt(I: ti.template(), t: ti.f32, h: ti.f32, atol: ti.f32, rtol: ti.f32, tol_g: ti.f32) -> ti.f32:
    """Step doubling from t by h into ``cand_pos``/``cand_vel`` (and the step's fastest impact into
    ``cand_hit*``); returns the scaled max-norm error."""
    S = I.state
    I.err[None] = 0.0
    for i in range(I.cap):
        if S.particle_alive[i] != 0:
            a0 = ti.min(S.particle_age[i], 0.0)
            if -a0 < h:
                y0 = _pack(S.particle_pos[i], ti.max(S.particle_age[i], 0.0), S.particle_vel[i])
                y, err, k, lag, xh, nh, speed, dv, stopped = I.advance(y0, t - a0, h + a0, i, atol, rtol, tol_g)
                S.cand_pos[i] = _x(y)
                S.cand_vel[i] = _v(y)
                if ti.static(I.located):
                    I.cand_hit[i] = (k + 1) * (1 - 2 * stopped)
                    if ti.static(I.record or I.events):
                        I.cand_hit_lag[i], I.cand_hit_pos[i], I.cand_hit_n[i] = lag, xh, nh
                        I.cand_hit_speed[i], I.cand_hit_dv[i] = speed, dv
                ti.atomic_max(I.err[None], err)
            else:
                S.cand_pos[i] = S.particle_pos[i]
                S.cand_vel[i] = S.particle_vel[i]
                if ti.static(I.located):
                    I.cand_hit[i] = 0
    return I.err[None]


@ti.kernel
def commit(I: ti.template(), t: ti.f32, h: ti.f32):
    """Accept the attempted step: hold contacts, record impacts, age, retire."""
    S = I.state
    zero = ti.Vector([0.0, 0.0, 0.0])
    for i in range(I.cap):
        I.clear_event(i)
        if S.particle_alive[i] != 0:
            if S.particle_age[i] + h > 0:
                k, lag, xh, nh, speed, dv, stopped = -1, 0.0, zero, zero, 0.0, 0.0, 0
                if ti.static(I.located):
                    c = I.cand_hit[i]
                    k, stopped = ti.abs(c) - 1, ti.cast(c < 0, ti.i32)
                    if ti.static(I.record or I.events):
                        lag, xh, nh = I.cand_hit_lag[i], I.cand_hit_pos[i], I.cand_hit_n[i]
                        speed, dv = I.cand_hit_speed[i], I.cand_hit_dv[i]
                I.finish(i, S.particle_pos[i], S.particle_vel[i], S.cand_pos[i], S.cand_vel[i], t + h, h, k, lag, xh, nh,
                         speed, dv, stopped)
            else:
                S.particle_age[i] += h  # not born yet


@ti.kernel
def count_alive(alive: ti.template(), n: ti.i32, dropped: ti.template(), r: ti.i32) -> ti.i32:
    """Live slots among the first n plus the births dropped by the first r emitters (integer
    reductions: the same count for any thread order). The live count (r = 0) a frame and the
    dropped total (n = 0) at a run's end are the one kernel: a second (``to_numpy``) was ~13 ms of
    every warm start."""
    c = 0
    for i in range(n):
        c += alive[i]
    for e in range(r):
        c += dropped[e]
    return c


def _by_integrator(kernel):
    """``kernel(I, *args)`` launched without Taichi's per-call Python (engine.launch: the
    integrator is a template argument, bound by a weak reference; several a frame in every
    particle scene), compiled lean where ``I.lean`` (above)."""
    plain, lean = fast(kernel), fast(kernel, lean=True)

    def launch(I, *args):
        return (lean if I.lean else plain)(I, *args)

    launch.__name__ = launch.__qualname__ = kernel.__name__
    return launch


step_fixed, step_fixed_run, attempt, commit = (
    _by_integrator(k) for k in (step_fixed, step_fixed_run, attempt, commit))
count_alive = fast(count_alive)

"""Particle stepping: the ODE core's steppers fused into one kernel per step.

Each particle's state is y = (x, age, v, 0) ∈ R⁸ with y' = (v, 1, a(x, v, age, t), 0); the
particles do not interact, so all stages of a method run in registers inside one parallel loop
(PERF-NOTES: one fused RK4 kernel is ~3× faster than stage kernels). Colliders and ageing run in
the same kernel after the step (:meth:`ParticleIntegrator.finish`). With step doubling,
``attempt`` writes a candidate and returns the max-norm error over live particles (a max is
order-independent, so the result does not depend on threads); ``commit`` accepts it.

The kernels are module-level over the :class:`ParticleIntegrator` (a template argument: its
stepper, forces and colliders are compile-time parts of it), warp.sim style; the particle system
(:mod:`.system`) launches them.
"""
import taichi as ti

from ..ode.steppers import doubling_step, is_finite, make_step, scaled_error

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


@ti.func
def no_collision(x, v):
    """``collide`` of a scene without colliders: nothing hit (the compiler drops the branches)."""
    return x, v, 0, 0, -1, ti.Vector([0.0, 0.0, 0.0]), 0.0


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


@ti.data_oriented
class ParticleIntegrator:
    """The compiled parts of a scene's particle step and what the step reports.

    ``collide``: the colliders' reporting function (``make_func(report=True)``; None: no
    colliders). With ``contacts`` > 0 up to that many contacts between drains are recorded in
    ``contact_*`` fields (slot, collider, position, normal, impact speed, time); without, the
    unused report outputs are dead code the compiler drops. With ``events`` each step records in
    ``particle_event`` who died (bit 1) or hit a collider (bit 2, |Δv| in ``particle_impact``)
    for the sub-emitters, after clearing the previous step's."""

    def __init__(self, state, accel, collide, method: str, adaptive: bool, extrapolate=False,
                 events: bool = False, contacts: int = 0):
        self.state, self.cap = state, state.capacity
        self.nonfinite_t = ti.field(ti.f32, shape=())
        self.err = ti.field(ti.f32, shape=())
        self.hits = ti.field(ti.i32, shape=())
        self.nonfinite_t[None] = NO_FAILURE
        self.has_colliders = collide is not None
        self.collide = collide if collide is not None else no_collision
        self.events = bool(events)
        self.record = bool(contacts) and self.has_colliders
        self.max_contacts = int(contacts)
        cn = max(1, int(contacts))
        self.contact_count = ti.field(ti.i32, shape=())
        self.contact_slot = ti.field(ti.i32, shape=cn)
        self.contact_collider = ti.field(ti.i32, shape=cn)
        self.contact_pos = ti.Vector.field(3, ti.f32, shape=cn)
        self.contact_normal = ti.Vector.field(3, ti.f32, shape=cn)
        self.contact_speed = ti.field(ti.f32, shape=cn)
        self.contact_time = ti.field(ti.f32, shape=cn)
        deriv, deriv_q = particle_derivative(accel)
        self.step = make_step(method, deriv, 8, ti.f32, fq=deriv_q)
        self.dstep = doubling_step(method, deriv, 8, ti.f32, extrapolate, fq=deriv_q) if adaptive else None

    @ti.func
    def finish(self, i, x, v, t_end, h):
        """Collide, age and retire particle i after an accepted step ending at t_end."""
        S = self.state
        if is_finite(x.sum() + v.sum()):
            killed = 0
            if ti.static(self.has_colliders):
                nx, nv, k, nh, which, nrm, spd = self.collide(x, v)
                if ti.static(self.record):
                    if nh > 0:
                        c = ti.atomic_add(self.contact_count[None], 1)  # order fixed later by (time, slot)
                        if c < self.max_contacts:
                            self.contact_slot[c], self.contact_collider[c], self.contact_pos[c] = i, which, nx
                            self.contact_normal[c], self.contact_speed[c], self.contact_time[c] = nrm, spd, t_end
                if ti.static(self.events):
                    if nh > 0:
                        S.particle_event[i] |= 2
                        S.particle_impact[i] = (nv - v).norm()
                x, v, killed = nx, nv, k
                if nh > 0:
                    ti.atomic_add(self.hits[None], nh)
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
            y = I.step(_pack(S.particle_pos[i], ti.max(S.particle_age[i], 0.0), S.particle_vel[i]),
                       t - a0, h + a0, i)
            I.finish(i, _x(y), _v(y), t + h, h)
        else:
            S.particle_age[i] += h  # not born yet


@ti.kernel
def step_fixed(I: ti.template(), t: ti.f32, h: ti.f32):
    """One step of h from t for every particle."""
    for i in range(I.cap):
        _step_one(I, i, t, h)


@ti.kernel
def step_fixed_run(I: ti.template(), t0: ti.f64, h: ti.f64, j: ti.i32, k: ti.i32):
    """Steps j … j + k − 1 of h from t0 in one launch, each particle taking them in registers one
    after the other: for a run of steps with nothing to do in between (no births due, colliders
    still, no sub-emitters). Step m starts at t0 + m·h, rounded to f32 from f64 as a launch of
    :func:`step_fixed` with that start would be: the same bytes as k launches."""
    for i in range(I.cap):
        for m in range(j, j + k):
            _step_one(I, i, ti.cast(t0 + m * h, ti.f32), ti.cast(h, ti.f32))


@ti.kernel
def attempt(I: ti.template(), t: ti.f32, h: ti.f32, atol: ti.f32, rtol: ti.f32) -> ti.f32:
    """Step doubling from t by h into ``cand_pos``/``cand_vel``; returns the scaled max-norm error."""
    S = I.state
    I.err[None] = 0.0
    for i in range(I.cap):
        if S.particle_alive[i] != 0:
            a0 = ti.min(S.particle_age[i], 0.0)
            if -a0 < h:
                y0 = _pack(S.particle_pos[i], ti.max(S.particle_age[i], 0.0), S.particle_vel[i])
                y2, est = I.dstep(y0, t - a0, h + a0, i)
                S.cand_pos[i] = _x(y2)
                S.cand_vel[i] = _v(y2)
                ti.atomic_max(I.err[None], scaled_error(y0, y2, est, atol, rtol))
            else:
                S.cand_pos[i] = S.particle_pos[i]
                S.cand_vel[i] = S.particle_vel[i]
    return I.err[None]


@ti.kernel
def commit(I: ti.template(), t: ti.f32, h: ti.f32):
    """Accept the attempted step: collide, age, retire."""
    S = I.state
    for i in range(I.cap):
        I.clear_event(i)
        if S.particle_alive[i] != 0:
            if S.particle_age[i] + h > 0:
                I.finish(i, S.cand_pos[i], S.cand_vel[i], t + h, h)
            else:
                S.particle_age[i] += h  # not born yet


@ti.kernel
def count_alive(alive: ti.template(), n: ti.i32) -> ti.i32:
    """Live slots among the first n (an integer reduction: the same count for any thread order)."""
    c = 0
    for i in range(n):
        c += alive[i]
    return c

"""Particle stepping: the ODE core's steppers fused into one kernel per step.

Each particle's state is y = (x, age, v, 0) ∈ R⁸ with y' = (v, 1, a(x, v, age, t), 0); the particles do not interact,
so all stages of a method run in registers inside one parallel loop (PERF-NOTES: one fused RK4
kernel is ~3× faster than stage kernels). Colliders and ageing run in the same kernel after the
step. With step doubling, ``attempt`` writes a candidate and returns the max-norm error over live
particles (a max is order-independent, so the result does not depend on threads); ``commit``
accepts it.
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


class ParticleIntegrator:
    def __init__(self, state, accel, collide, method: str, adaptive: bool, extrapolate=False,
                 events: bool = False, contacts: int = 0):
        """``collide`` is the colliders' reporting function (``make_func(report=True)``; None: no
        colliders). With ``contacts`` > 0 up to that many contacts per frame are recorded in
        ``contact_*`` fields (slot, collider, position, normal, impact speed, time); without, the
        unused report outputs are dead code the compiler drops."""
        S = state
        pos, vel, age, life, alive = (S.particle_pos, S.particle_vel, S.particle_age,
                                      S.particle_life, S.particle_alive)
        cap = state.capacity
        self.nonfinite_t = ti.field(ti.f32, shape=())
        self.err = ti.field(ti.f32, shape=())
        self.hits = ti.field(ti.i32, shape=())
        self.nonfinite_t[None] = NO_FAILURE
        bad_t, err, hits = self.nonfinite_t, self.err, self.hits
        has_colliders = collide is not None
        record = bool(contacts) and has_colliders
        self.max_contacts = int(contacts)
        self.contact_count = ti.field(ti.i32, shape=())
        cn = max(1, int(contacts))
        self.contact_slot = c_slot = ti.field(ti.i32, shape=cn)
        self.contact_collider = c_coll = ti.field(ti.i32, shape=cn)
        self.contact_pos = c_pos = ti.Vector.field(3, ti.f32, shape=cn)
        self.contact_normal = c_nrm = ti.Vector.field(3, ti.f32, shape=cn)
        self.contact_speed = c_spd = ti.field(ti.f32, shape=cn)
        self.contact_time = c_t = ti.field(ti.f32, shape=cn)
        c_count, c_max = self.contact_count, int(contacts)
        event = impact = None
        if events:
            event, impact = S.particle_event, S.particle_impact

        @ti.func
        def deriv(y, t, i):
            v = _v(y)
            return _pack(v, 1.0, accel(_x(y), v, y[3], t, i))

        @ti.func
        def deriv_q(y, t, i):  # (x, age)' = (v, 1): all the drift of a partitioned method needs
            return _pack(_v(y), 1.0, ti.Vector([0.0, 0.0, 0.0]))

        @ti.func
        def finish(i, x, v, t_end, h):
            """Collide, age and retire one particle after an accepted step."""
            if is_finite(x.sum() + v.sum()):
                killed = 0
                if ti.static(has_colliders):
                    nx, nv, k, nh, which, nrm, spd = collide(x, v)
                    if ti.static(record):
                        if nh > 0:
                            c = ti.atomic_add(c_count[None], 1)  # order fixed later by (time, slot)
                            if c < c_max:
                                c_slot[c], c_coll[c], c_pos[c] = i, which, nx
                                c_nrm[c], c_spd[c], c_t[c] = nrm, spd, t_end
                    if ti.static(events):
                        if nh > 0:
                            event[i] |= 2
                            impact[i] = (nv - v).norm()
                    x, v, killed = nx, nv, k
                    if nh > 0:
                        ti.atomic_add(hits[None], nh)
                pos[i] = x
                vel[i] = v
                a = age[i] + h
                age[i] = a
                if a >= life[i] or killed != 0:
                    alive[i] = 0
                    if ti.static(events):
                        event[i] |= 1
            else:
                ti.atomic_min(bad_t[None], t_end)
                alive[i] = 0

        step = make_step(method, deriv, 8, ti.f32, fq=deriv_q)

        @ti.kernel
        def step_fixed(t: ti.f32, h: ti.f32):
            for i in range(cap):
                if alive[i] != 0:
                    a0 = ti.min(age[i], 0.0)  # < 0: born a0 seconds into this step
                    if -a0 < h:
                        y = step(_pack(pos[i], ti.max(age[i], 0.0), vel[i]), t - a0, h + a0, i)
                        finish(i, _x(y), _v(y), t + h, h)
                    else:
                        age[i] += h  # not born yet

        self.step_fixed = step_fixed

        if adaptive:
            cpos, cvel = S.cand_pos, S.cand_vel
            dstep = doubling_step(method, deriv, 8, ti.f32, extrapolate, fq=deriv_q)

            @ti.kernel
            def attempt(t: ti.f32, h: ti.f32, atol: ti.f32, rtol: ti.f32) -> ti.f32:
                err[None] = 0.0
                for i in range(cap):
                    if alive[i] != 0:
                        a0 = ti.min(age[i], 0.0)
                        if -a0 < h:
                            y0 = _pack(pos[i], ti.max(age[i], 0.0), vel[i])
                            y2, est = dstep(y0, t - a0, h + a0, i)
                            cpos[i] = _x(y2)
                            cvel[i] = _v(y2)
                            ti.atomic_max(err[None], scaled_error(y0, y2, est, atol, rtol))
                        else:
                            cpos[i] = pos[i]
                            cvel[i] = vel[i]
                return err[None]

            @ti.kernel
            def commit(t: ti.f32, h: ti.f32):
                for i in range(cap):
                    if alive[i] != 0:
                        if age[i] + h > 0:
                            finish(i, cpos[i], cvel[i], t + h, h)
                        else:
                            age[i] += h  # not born yet

            self.attempt, self.commit = attempt, commit

        @ti.kernel
        def count_alive() -> ti.i32:
            n = 0
            for i in range(cap):
                n += alive[i]
            return n

        self.count_alive = count_alive

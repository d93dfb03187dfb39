"""Rigid bodies on the ODE path: Baraff's state Y = (x, q, P, L) per body stepped by any of the
five integrators through the engine's one stepper library and Driver (fixed steps of [solver] h,
or step doubling with its tolerances), in float64.

Ẏ = (v, ½[ω, 0]q, M g, 0) with v = P/M, ω = R I_b⁻¹ Rᵀ L (Baraff, "Rigid Body Simulation",
SIGGRAPH notes): with no torque L is constant for every method, exactly (its derivative is zero),
so torque-free rotation keeps L to rounding and the energy to the method's order. The state is 14
numbers, (x, q | P, L, 0), so the kick–drift splittings see q-half (x, q) and p-half (P, L); q is
normalised after every step.

Contacts with the scene's planes after each step: the deepest point of a body below a plane is
put back on it, and if it approaches, Baraff's impulse j = −(1 + e) v_n / (1/M + n·((I⁻¹(r × n)) ×
r)) with Coulomb friction (a tangential impulse of at most μ j that stops the sliding point at
most); e = 0 when |v_n| ≤ 2|g|h, so resting contact neither sinks nor jitters.

Body–body contacts after each step, the same way for two bodies: the broad and narrow phases of
the XPBD path (:meth:`RigidSystem.pair_contacts`: boxes by separating axes, the other pairs in
closed form), each penetration taken out along n split by inverse mass (translation only), then
Baraff's two-body impulse j = −(1 + e) v_rel·n / (k_a + k_b), k = 1/M + n·((I⁻¹(r × n)) × r), with
Coulomb friction, swept over the contacts in their fixed order (sequential impulses: a stack needs
several sweeps, CONTACT_SWEEPS). Impacts are located inside the step (:mod:`engine.rigid.locate`):
the step is ended at the first one, the contacts respond there, and the rest is taken from there.
e is the larger of the two bodies' restitutions and μ the mean of their frictions, as on the XPBD
path."""
# (no __future__ annotations: Taichi reads the funcs' annotations)

import numpy as np
import taichi as ti

from ..ode.driver import Driver, StepPolicy
from ..ode.methods import method as ode_method
from ..ode.steppers import doubling_step, make_step, scaled_error
from . import collide, locate, quat
from .quat import cross

N = 14
MARGIN = 0.005  # m: body–body contacts this close take impulses (penetrations are moved out)
CONTACT_SWEEPS = 4  # sequential-impulse sweeps over the body–body contacts after a step


class BaraffSystem:
    """The Driver's protocol over every body's Y. ``owner``: the RigidSystem (model, state,
    control, colliders); ``solver_cfg``: the scene's [solver] (h, adaptive, tolerance, atol)."""

    def __init__(self, owner, solver_cfg):
        self.owner, self.model = owner, owner.model
        m = self.model
        self.method = owner.settings.integrator
        self.label = f"{owner.name}: {self.method}"
        self.order = ode_method(self.method).order
        n = max(1, m.count)
        self.Y = ti.Vector.field(N, ti.f64, n)
        self.Y0 = ti.Vector.field(N, ti.f64, n)
        self.inv_m = ti.field(ti.f64, n)
        self.inv_i = ti.Vector.field(3, ti.f64, n)
        self.g = ti.Vector.field(3, ti.f64, ())
        self.err = ti.field(ti.f64, ())
        self.inv_m.from_numpy(_pad(m.body_inv_mass, n))
        self.inv_i.from_numpy(_pad(m.body_inv_inertia, n))
        self.n = m.count
        self.rtol = solver_cfg.tolerance
        self.atol = solver_cfg.atol if solver_cfg.atol is not None else solver_cfg.tolerance
        self.h = solver_cfg.h
        # whether the bodies can meet anything (else no step pays for impacts): Y0 is kept by every
        # step then, for locating impacts inside it (engine.rigid.locate)
        self.touches = (bool(m.count) and bool(m.dynamic.any()) and (bool(owner.specs) or m.count > 1)
                        and getattr(solver_cfg, "impacts", "located") == "located")
        self._k = _build(self)
        self.driver = Driver(self, StepPolicy(h=solver_cfg.h, adaptive=solver_cfg.adaptive, rtol=self.rtol,
                                              atol=self.atol), owner.stats)
        self._bad = None
        self._g = np.zeros(3)
        self.load()

    # -- state in and out ---------------------------------------------------------------------
    def load(self) -> None:
        """Y from the owner's (x, q, v, ω)."""
        S, m = self.owner.state, self.model
        Y = np.zeros((max(1, m.count), N))
        if m.count:
            Y[: m.count, 0:3] = S.x
            Y[: m.count, 3:7] = S.q
            Y[: m.count, 7:10] = S.v * m.body_mass[:, None]
            wb = quat.rotate_inv(S.q, S.w)
            Y[: m.count, 10:13] = quat.rotate(S.q, m.body_inertia * wb)
        self.Y.from_numpy(Y)

    def store(self, Y=None) -> None:
        """The owner's (x, q, v, ω) from Y."""
        S, m = self.owner.state, self.model
        if m.count == 0:
            return
        Y = self.Y.to_numpy()[: m.count] if Y is None else Y
        S.x[:] = Y[:, 0:3]
        S.q[:] = Y[:, 3:7]
        S.v[:] = Y[:, 7:10] / m.body_mass[:, None]
        wb = quat.rotate_inv(S.q, Y[:, 10:13]) / np.maximum(m.body_inertia, 1e-300)
        S.w[:] = np.where(m.dynamic[:, None], quat.rotate(S.q, wb), S.w)

    def reset(self) -> None:
        self.driver.reset()
        self._bad = None
        self.load()

    def advance(self, t0: float, t1: float, g) -> None:
        self._g = np.asarray(g, np.float64)
        self.g[None] = self._g.tolist()
        self.driver.advance(t0, t1)
        self.store()

    # -- the Driver's protocol -----------------------------------------------------------------
    def fixed_step(self, t0, h, j, n):
        t, left = t0 + j * h, h
        self._k["step"](t, left)
        Y = None
        for _ in range(locate.MAX_EVENTS):  # impacts located inside the step (engine.rigid.locate)
            tau = self.locate(t, left)
            if tau is None:
                Y = self._Y1  # (the state the search read: the step's end)
                break
            self._k["rollback"]()
            self._k["step"](t, tau)
            self._contacts(h, touch=locate.TOUCHING)  # the response, where the impact is
            t, left = t + tau, left - tau
            self._k["step"](t, left)
        self._contacts(h, Y=Y)
        return 1

    def locate(self, t, h):
        """The time (s after t) of the first impact inside the step just taken from Y0 at t for
        h, or None (engine.rigid.locate). The state is left at the step's end either way."""
        self._Y1 = None
        if not self.touches:
            return None
        n = self.n
        self._Y1 = Y1 = self.Y.to_numpy()
        stepped = []

        def step_to(tau):
            self._k["rollback"]()
            if self.driver.policy.adaptive:
                self._k["attempt"](t, tau, self.atol, self.rtol)
            else:
                self._k["step"](t, tau)
            stepped.append(tau)
            return self.Y.to_numpy()[:n]

        tau = locate.locate(self.owner, lambda: self.Y0.to_numpy()[:n], Y1[:n], h, float(np.linalg.norm(self._g)),
                            step_to)
        if stepped:
            self.Y.from_numpy(Y1)
        return tau

    def attempt(self, t, h):
        return float(self._k["attempt"](t, h, self.atol, self.rtol))

    def commit(self, t, h):
        self._contacts(h, touch=locate.TOUCHING)  # (a step the driver ended at an impact ends touching)

    def rollback(self):
        self._k["rollback"]()

    def first_nonfinite(self):
        if self.n and not np.isfinite(self.Y.to_numpy()[: self.n]).all():
            return self.owner.t
        return None

    # -- contacts with the scene's planes --------------------------------------------------------
    def _contacts(self, h: float, touch: float = 0.0, Y=None) -> None:
        """The end-of-step response; ``touch`` (m): a point this close above a plane counts as on
        it (a located impact ends its step touching, a rounding's width either side); ``Y``: the
        state as already read back, if it was."""
        own, m = self.owner, self.model
        planes = [(k, s) for k, s in enumerate(own.specs) if s.kind == "plane"]
        shapes = [(k, s) for k, s in enumerate(own.specs) if s.kind != "plane"]
        pairs = m.count > 1 and m.dynamic.any()
        if not (planes or shapes or pairs) or m.count == 0:
            return
        Y = self.Y.to_numpy() if Y is None else Y
        y = Y[: m.count]
        gl = float(np.linalg.norm(self._g))
        pos = own.control.collider_positions(own.t)
        changed = False
        R = quat.matrix(y[:, 3:7]) if planes else None
        for k, spec in planes:
            nrm = np.asarray(spec.normal, np.float64)
            nrm = nrm / np.linalg.norm(nrm)
            idx, pas, pbs = collide.plane_contacts(m, y[:, 0:3], R, pos[k], nrm, np.full(m.count, touch),
                                                   np.flatnonzero(m.dynamic))
            deepest = {}
            for i, pa, pb in zip(idx.tolist(), pas, pbs):  # one contact per body and plane: the deepest
                d = float(np.dot(pb - pa, nrm))
                if i not in deepest or d > deepest[i][0]:
                    deepest[i] = (d, pa, nrm)
            for i, (d, pa, n) in sorted(deepest.items()):
                changed = True
                y[i, 0:3] += d * n  # back onto the plane
                pa = pa + d * n
                self._impulse(y, i, pa, n, float(spec.restitution), 0.5 * (m.body_friction[i] + spec.friction), gl, h)
        if shapes or pairs:
            changed |= self._solid_contacts(y, shapes, pos, gl, h)
        if changed:
            y[:, 3:7] = quat.normalize(y[:, 3:7])
            self.Y.from_numpy(Y)

    def _solid_contacts(self, y, shapes, pos, gl, h) -> bool:
        """Contacts of the bodies as ``y`` (B, 14) holds them with the scene's sphere, box and
        capsule colliders (``shapes``: (index, spec), placed at ``pos``) and with each other:
        penetrations taken out, then CONTACT_SWEEPS sweeps of impulses (module docstring).
        Whether there were any."""
        own, m = self.owner, self.model
        R = quat.matrix(y[:, 3:7]) if shapes else None  # (else only the pairs' bodies need it)
        # contacts within MARGIN count (a box resting on another keeps all four corners of its
        # manifold, not the one or two that happen to be inside after a step: those alone would
        # rock it); only penetrations are moved
        margins = np.full(m.count, 0.5 * MARGIN)
        a, b, pa, pb, n, e, mu = [], [], [], [], [], [], []
        for k, spec in shapes:  # b = −1: the world
            for i, ca, cb, cn in own.static_shape_contacts(k, spec, pos[k], own.t, y[:, 0:3], R, margins,
                                                           np.flatnonzero(m.dynamic)):
                a.append(i)
                b.append(-1)
                pa.append(ca)
                pb.append(cb)
                n.append(cn)
                e.append(max(m.body_restitution[i], spec.restitution))
                mu.append(0.5 * (m.body_friction[i] + spec.friction))
        got = own.pair_contacts(y[:, 0:3], R, margins, m.dynamic, q=y[:, 3:7]) if m.count > 1 else None
        if got is not None:
            i, j, ca, cb, cn = got
            a += i.tolist()
            b += j.tolist()
            pa += list(ca)
            pb += list(cb)
            n += list(cn)
            e += np.maximum(m.body_restitution[i], m.body_restitution[j]).tolist()
            mu += (0.5 * (m.body_friction[i] + m.body_friction[j])).tolist()
        if not a:
            return False
        pa, pb, n = np.array(pa), np.array(pb), np.array(n)
        depth = np.einsum("ij,ij->i", pb - pa, n)
        for k in range(len(a)):  # out of each other along n, split by inverse mass
            wa = m.body_inv_mass[a[k]]
            wb = m.body_inv_mass[b[k]] if b[k] >= 0 else 0.0
            if wa + wb > 0.0 and depth[k] > 0.0:
                y[a[k], 0:3] += depth[k] * (wa / (wa + wb)) * n[k]
                if b[k] >= 0:
                    y[b[k], 0:3] -= depth[k] * (wb / (wa + wb)) * n[k]
        p = 0.5 * (pa + pb)  # the contact point, midway between the two surfaces
        for _ in range(CONTACT_SWEEPS):
            for k in range(len(a)):
                self._impulse(y, a[k], p[k], n[k], float(e[k]), float(mu[k]), gl, h, other=int(b[k]))
        return True

    def _impulse(self, y, i, p, n, e, mu, gl, h, other: int = -1) -> None:
        """Baraff's impulse at the contact point p (normal n toward body i) between body i and
        ``other`` (−1: the world, at rest), with Coulomb friction (at most μj, and no more than
        stops the sliding); e = 0 for an approach slower than 2|g|h (resting contact)."""
        m = self.model
        bodies = (i,) if other < 0 else (i, other)
        r, Iinv, vp = {}, {}, np.zeros(3)
        for s, c in zip(bodies, (1.0, -1.0)):
            r[s] = p - y[s, 0:3]
            Iinv[s] = (lambda q_, s_: lambda v: quat.rotate(q_, m.body_inv_inertia[s_] * quat.rotate_inv(q_, v)))(y[s, 3:7], s)
            w = Iinv[s](y[s, 10:13])
            vp = vp + c * (y[s, 7:10] * m.body_inv_mass[s] + cross(w, r[s]))
        vn = float(np.dot(vp, n))
        if vn >= 0.0:
            return
        if -vn <= 2.0 * gl * h:
            e = 0.0  # resting: no bounce

        def k_along(d):  # 1/M + d·((I⁻¹(r × d)) × r), summed over the bodies
            return sum(m.body_inv_mass[s] + float(np.dot(d, cross(Iinv[s](cross(r[s], d)), r[s]))) for s in bodies)

        j = -(1.0 + e) * vn / k_along(n)
        J = j * n
        vt = vp - vn * n
        vt_len = float(np.linalg.norm(vt))
        if vt_len > 1e-12:
            t = vt / vt_len
            J = J - min(mu * j, vt_len / k_along(t)) * t
        for s, c in zip(bodies, (1.0, -1.0)):
            if m.body_inv_mass[s] > 0.0:  # a fixed body takes no impulse
                y[s, 7:10] += c * J
                y[s, 10:13] += c * cross(r[s], J)


def _pad(a, n):
    out = np.zeros((n,) + np.asarray(a).shape[1:])
    out[: len(a)] = a
    return out


def _build(sys: BaraffSystem):
    Y, Y0, inv_m, inv_i, g, err = sys.Y, sys.Y0, sys.inv_m, sys.inv_i, sys.g, sys.err
    n, dtype = max(1, sys.model.count), ti.f64

    @ti.func
    def f(y, t, i):
        q = ti.Vector([y[3], y[4], y[5], y[6]], dt=dtype)
        q = q / q.norm()
        u = ti.Vector([q[1], q[2], q[3]], dt=dtype)
        L = ti.Vector([y[10], y[11], y[12]], dt=dtype)
        # ω = R I⁻¹ Rᵀ L
        tt = 2.0 * (-u).cross(L)
        Lb = L + q[0] * tt + (-u).cross(tt)
        wb = inv_i[i] * Lb
        t2 = 2.0 * u.cross(wb)
        w = wb + q[0] * t2 + u.cross(t2)
        dq = 0.5 * ti.Vector([-w[0] * q[1] - w[1] * q[2] - w[2] * q[3],
                              w[0] * q[0] + w[1] * q[3] - w[2] * q[2],
                              -w[0] * q[3] + w[1] * q[0] + w[2] * q[1],
                              w[0] * q[2] - w[1] * q[1] + w[2] * q[0]], dt=dtype)
        v = inv_m[i] * ti.Vector([y[7], y[8], y[9]], dt=dtype)
        F = ti.Vector([0.0, 0.0, 0.0], dt=dtype)
        if inv_m[i] > 0.0:
            F = g[None] / inv_m[i]
        return ti.Vector([v[0], v[1], v[2], dq[0], dq[1], dq[2], dq[3], F[0], F[1], F[2], 0.0, 0.0, 0.0, 0.0],
                         dt=dtype)

    step = make_step(sys.method, f, N, dtype)
    dstep = doubling_step(sys.method, f, N, dtype)

    @ti.func
    def normalised(y):
        s = ti.sqrt(y[3] * y[3] + y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
        for c in ti.static(range(3, 7)):
            y[c] = y[c] / s
        return y

    @ti.kernel
    def step_k(t: dtype, h: dtype):
        for i in range(n):
            if ti.static(sys.touches):
                Y0[i] = Y[i]  # (kept for locating an impact inside the step)
            Y[i] = normalised(step(Y[i], t, h, i))

    @ti.kernel
    def attempt_k(t: dtype, h: dtype, atol: dtype, rtol: dtype) -> dtype:
        err[None] = 0.0
        for i in range(n):
            y0 = Y[i]
            Y0[i] = y0
            y2, est = dstep(y0, t, h, i)
            ti.atomic_max(err[None], scaled_error(y0, y2, est, atol, rtol))  # max: any order
            Y[i] = normalised(y2)
        return err[None]

    @ti.kernel
    def rollback_k():
        for i in range(n):
            Y[i] = Y0[i]

    return dict(step=step_k, attempt=attempt_k, rollback=rollback_k)

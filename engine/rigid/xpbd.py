"""XPBD for rigid bodies (Müller, Macklin, Chentanez, Jeschke, Kim 2020, "Detailed Rigid Body
Simulation with Extended Position Based Dynamics"), substep by substep:

1. integrate: v += h g; x += h v; ω += h I⁻¹(−ω × Iω) (body frame); q += ½h[ω, 0]q, normalised;
2. position solve: joints (in config order; the point constraints of joints that share a moving
   body together, by a direct solve: :mod:`.joints`), then every contact's depth d = (p_b − p_a)·n,
   Δλ = d / (w_a + w_b) with w = 1/m + (r × n)ᵀ I⁻¹ (r × n), then static friction, which undoes
   the contact points' tangential slip where its Δλ_t < μ λ_n;
3. v = Δx/h, ω = 2 vec(Δq q⁻¹)/h;
4. velocity solve: dynamic friction (a tangential impulse of at most μ λ_n / h) and restitution
   (v_n ← −e ṽ_n, the normal velocity before the substep; e = 0 when |ṽ_n| ≤ 2|g|h).

Determinism: contacts are kept in a fixed order (the static shapes', then sorted body pairs) and
solved Gauss–Seidel in that order by serial kernel loops (:mod:`.kernel`): no sum depends on a
thread's timing, so 1 and 2 threads give the same bytes.
Friction combines the two materials' μ by their average (two μ = 0.5 slide as μ = 0.5),
restitution by the larger e.
"""
from __future__ import annotations

import numpy as np

from . import fields, pool, quat
from .shapes import SPHERE


class ContactSet:
    """The contacts of one rigid step, fixed over its substeps, in a fixed order: ``a``, ``b``
    (negative: the world; −1 − k for the scene's static shape k), normal ``n`` (from b to a), anchors in the body frames (``ra``; ``rb``, a
    world point when b = −1), ``round_a``/``round_b`` (a sphere's radius: its anchor is re-aimed
    along ∓n each substep, so a rolling ball keeps touching at its lowest point), ``mu``
    (average of the two), ``e`` (the larger), ``lam`` (the last substep's normal multipliers),
    ``depth`` (at the step's start) and ``source`` (what b is: a body's or a collider's name)."""

    def __init__(self, model, state, a, b, pa, pb, n, mu_b, e_b, statics=()):
        K = len(a)
        self.count = K
        self.a, self.b = np.asarray(a, np.int32), np.asarray(b, np.int32)
        self.n = np.ascontiguousarray(n, np.float64).reshape(K, 3)
        a, b = self.a, self.b
        has_b = b >= 0
        bb = np.where(has_b, b, 0)
        self.ra = quat.rotate_inv(state.q[a], pa - state.x[a])
        self.rb = np.where(has_b[:, None], quat.rotate_inv(state.q[bb], pb - state.x[bb]), pb)
        self.round_a = np.where(model.body_shape[a] == SPHERE, model.body_radius[a], 0.0)
        self.round_b = np.where(has_b & (model.body_shape[bb] == SPHERE), model.body_radius[bb], 0.0)
        self.mu = 0.5 * (model.body_friction[a] + mu_b)
        self.e = np.maximum(model.body_restitution[a], e_b)
        self.lam = np.zeros(K)
        self.depth = np.einsum("ij,ij->i", pb - pa, self.n)
        self._names, self._statics = model.names, list(statics)

    @property
    def source(self) -> list:
        """What each contact's b is: a body's name, or a static shape's (b = −1 − its index)."""
        return [self._names[k] if k >= 0 else self._statics[-1 - k] for k in self.b.tolist()]


class XPBDSolver:
    """Steps a :class:`~engine.rigid.model.RigidState` (NumPy, float64) by substeps on float64
    fields (:class:`~engine.rigid.fields.Fields`: copied in and out once per step).
    ``joints``: a :class:`~engine.rigid.joints.Joints`. ``awake``: bodies asleep hold still like
    fixed ones (no integration, zero inverse mass)."""

    def __init__(self, model, state, joints=None, capacity: int = 0):
        self.model, self.state, self.joints = model, state, joints
        self.awake = np.ones(model.count, bool)
        self.nj = len(joints) if joints is not None else 0
        self._lease = None  # pool.Lease: pooled fields, back to the pool with this solver
        # room for a box's 8-point manifolds with its neighbours: growing recompiles the kernels
        self._capacity = max(1024, capacity, 24 * model.count)

    def _fields(self, nc: int):
        if self._lease is None or nc > self._lease.F.capacity:
            cap = self._capacity
            while cap < nc:
                cap *= 2
            self._capacity = cap
            m = self.model
            plan = self.joints.direct_plan() if self.nj else None
            self._lease = None  # the outgrown fields go back to the pool first
            self._lease = pool.lease(m.count, cap, self.nj, plan)
            F = self._lease.F
            F.inertia.from_numpy(_pad(m.body_inertia, F.nb))
            F.kin.from_numpy(_pad(m.body_kinematic.astype(np.int32), F.nb))
            if self.nj:
                names = "jt ja jb jra jrb jaxa jaxb jpa jpb jqrel jlo jhi jlim jalpha".split()
                for k, arr in zip(names, self.joints.arrays()[1:]):
                    getattr(F, k).from_numpy(_pad(arr, F.nj))
                F.jdir.from_numpy(_pad(plan["flag"], F.nj))
            F.substeps(0, 0.0, [0.0, 0.0, 0.0], 0.0, 0, 0)  # compile now (pooled: compiled)
        return self._lease.F

    def step(self, h: float, substeps: int, g, C: ContactSet, kinematic=None) -> None:
        """``substeps`` substeps of h/substeps under gravity g with the step's contacts C.
        ``kinematic``: (positions at the step's start, at its end) of path-following bodies."""
        m, S = self.model, self.state
        if m.count == 0:
            return
        F = self._fields(C.count)
        nb = F.nb
        mov = m.dynamic & self.awake
        n = m.count
        rows = np.zeros((nb, fields.BODY_COLS))
        rows[:n, 0] = m.body_inv_mass * mov
        rows[:n, 1:4] = m.body_inv_inertia * mov[:, None]
        rows[:n, 4] = mov
        rows[:n, 5:8], rows[:n, 8:12], rows[:n, 12:15], rows[:n, 15:18] = S.x, S.q, S.v, S.w
        if kinematic is not None:
            rows[:n, 18:21], rows[:n, 21:24] = kinematic[0], kinematic[1]
        F.load_bodies(rows, int(kinematic is not None))
        nc = C.count
        if nc:
            c = np.empty((nc, fields.CONTACT_COLS))
            c[:, 0], c[:, 1], c[:, 2:5], c[:, 5:8], c[:, 8:11] = C.a, C.b, C.n, C.ra, C.rb
            c[:, 11], c[:, 12], c[:, 13], c[:, 14] = C.round_a, C.round_b, C.mu, C.e
            F.load_contacts(c)
        g = np.asarray(g, np.float64)
        glen, hs = float(np.linalg.norm(g)), h / substeps
        F.substeps(substeps, hs, g.tolist(), glen, nc, self.nj)
        out, lam = np.empty((n, 13)), np.empty(max(1, nc))
        F.store(out, lam)
        S.x[:], S.q[:], S.v[:], S.w[:] = out[:, 0:3], out[:, 3:7], out[:, 7:10], out[:, 10:13]
        if nc:
            C.lam[:] = lam[:nc]


def _pad(a, n):
    a = np.asarray(a)
    if len(a) == n:
        return np.ascontiguousarray(a)
    out = np.zeros((n,) + a.shape[1:], a.dtype)
    out[: len(a)] = a
    return out

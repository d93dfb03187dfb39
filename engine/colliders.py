"""Plane and sphere colliders, static or moving, shared by particles and spring nodes.

A collider is an *event set* for the ODE core's event location (:mod:`engine.ode.events`): its
contact function g is the signed distance from its surface (negative inside), g = (x − p)·N for a
plane and |x − c| − R for a sphere (NUMERICS.md, "Collisions"), evaluated against where the
collider is at the same time — a collider moves linearly over a step, from ``collider_point −
collider_vel·h`` to ``collider_point``, so at ``lag`` seconds before the step's end it is at
``collider_point − collider_vel·lag``.

Response (Witkin & Baraff, *Particle System Dynamics*; NUMERICS.md), in the collider's frame so a
moving collider pushes what it hits: with v_r = v − v_c, v_n = (N·v_r)N, v_t = v_r − v_n,
v_r' = v_t' − e v_n with Coulomb-style friction v_t' = max(0, 1 − μ(1 + e)|v_n|/|v_t|) v_t; the
point is put on the surface. Energy (in the collider's frame) never grows for e ≤ 1.

Held (resting) contact: a point that ends a step inside a collider is projected back
(:meth:`Colliders.project`); if it started the step touching that collider and its rebound e|v_n|
would be no more than what the step's own acceleration takes out of it (−N·Δv over the step: the
rebound would land within about two steps) it rests — v_n' = 0, friction with e = 0 — so a
particle lying on the ground is held there, not bounced and re-detected at every step (the end
of a bouncing ball's Zeno series).

The set of colliders is fixed when a scene is finalised: their count is a compile-time constant
and the per-collider loop is unrolled with ``ti.static``, so a scene with no colliders compiles no
collision code. Their positions live in fields, set from the scene's Control (engine.control)
before each step: moving one costs no recompilation.
"""
# (no __future__ annotations: Taichi reads the funcs' ti.template() annotations)

from dataclasses import dataclass, field
from typing import List, Sequence

import numpy as np
import taichi as ti

from .ode.events import contact_band

PLANE, SPHERE = 0, 1


@dataclass
class ColliderSpec:
    """One collider. ``kind`` is "plane" (point, normal) or "sphere" (center = point, radius).
    ``path`` is an optional list of (time, position) keyframes moving ``point``."""

    kind: str
    point: Sequence[float] = (0.0, 0.0, 0.0)
    normal: Sequence[float] = (0.0, 1.0, 0.0)
    radius: float = 1.0
    restitution: float = 0.5
    friction: float = 0.0
    kill: bool = False
    name: str = ""
    path: List = field(default_factory=list)
    visible: bool = True
    rigid: bool = False  # stands for a rigid body's sphere (moved from its published pose)

    def position_at(self, t: float) -> np.ndarray:
        from .paths import sample_path

        return sample_path(self.path, t, self.point)


@ti.data_oriented
class Colliders:
    """Fields for a fixed list of colliders and the ``ti.func`` s that find and resolve contacts.

    Fields (shape (count,), ``dtype``: f32 for scenes, f64 for reference runs): ``collider_point``
    (plane point or sphere centre at the end of the current step, m), ``collider_normal`` (unit,
    planes), ``collider_radius`` (m), ``collider_vel`` (m/s over the current step),
    ``collider_restitution``, ``collider_friction``. ``shift`` (count, 3): an offset added to
    every position (a soft body keeps its thickness from a plane by a copy of it moved along the
    normal). ``count``, ``kinds`` and ``kills`` are compile-time constants of the kernels.
    """

    def __init__(self, specs: Sequence[ColliderSpec], shift=None, dtype=ti.f32):
        self.specs = list(specs)
        self.count = len(self.specs)
        self.dtype = dtype
        self.kinds = tuple(PLANE if s.kind == "plane" else SPHERE for s in self.specs)
        self.kills = tuple(bool(s.kill) for s in self.specs)
        n = max(1, self.count)
        self.collider_point = ti.Vector.field(3, dtype, shape=n)
        self.collider_normal = ti.Vector.field(3, dtype, shape=n)
        self.collider_radius = ti.field(dtype, shape=n)
        self.collider_vel = ti.Vector.field(3, dtype, shape=n)
        self.collider_restitution = ti.field(dtype, shape=n)
        self.collider_friction = ti.field(dtype, shape=n)
        self._np = np.float64 if dtype == ti.f64 else np.float32
        self._pos = np.zeros((n, 3), self._np)
        self.shift = np.zeros((self.count, 3)) if shift is None else np.asarray(shift, np.float64).reshape(-1, 3)
        for k, s in enumerate(self.specs):
            nrm = np.asarray(s.normal, np.float64)
            self.collider_normal[k] = (nrm / np.linalg.norm(nrm)).tolist()
            self.collider_radius[k] = float(s.radius)
            self.collider_restitution[k] = float(s.restitution)
            self.collider_friction[k] = float(s.friction)
            self._pos[k] = s.position_at(0.0) + self.shift[k]
        self.collider_point.from_numpy(self._pos)
        self._t = 0.0
        self._band = contact_band(dtype)
        self._moved = False

    def reset(self) -> None:
        """Back where the specs start, at rest, at t = 0 (a reused scene)."""
        if self._moved:
            for k, s in enumerate(self.specs):
                self._pos[k] = s.position_at(0.0) + self.shift[k]
            self.collider_point.from_numpy(self._pos)
            self.collider_vel.from_numpy(np.zeros_like(self._pos))
        self._t, self._moved = 0.0, False

    def _placed(self, positions) -> np.ndarray:
        # (the control may hold more colliders after these: rigid bodies' spheres for particles)
        pos = np.asarray(positions, np.float64).reshape(-1, 3)[: self.count]
        return (pos + self.shift).astype(self._np) if self.shift.any() else pos.astype(self._np)

    def move_to(self, t: float, positions=None, since=None) -> None:
        """Set the colliders' positions for time t (``positions`` (count, 3), else from their
        specs' paths). Their velocities: over the step ``since = (t0, positions at t0)`` when
        given (a step's start, so a retried shorter step infers the same motion), else from the
        motion since the last call."""
        if self.count == 0:
            return
        new = self._placed([s.position_at(t) for s in self.specs] if positions is None else positions)
        t0, old = (since[0], self._placed(since[1])) if since is not None else (self._t, self._pos[: self.count])
        dt = t - t0
        vel = (new - old) / dt if dt > 0 else np.zeros_like(new)
        self._pos[: self.count] = new
        self._t, self._moved = t, True
        self.collider_point.from_numpy(self._pos)
        v = np.zeros_like(self._pos)
        v[: self.count] = vel
        self.collider_vel.from_numpy(v)

    def placement(self) -> bytes:
        """Where the colliders are now, as bytes (normals and radii never change): what a cached
        background depends on. Read from the host copy, so it costs no kernel launch."""
        shown = [k for k, s in enumerate(self.specs) if s.visible]
        return self._pos[shown].tobytes()

    def index(self, name: str) -> int:
        for k, s in enumerate(self.specs):
            if s.name == name:
                return k
        raise KeyError(f"collider: no collider named {name!r} "
                       f"(names: {', '.join(repr(s.name) for s in self.specs if s.name) or 'none'})")

    # -- the event set (engine.ode.events) ---------------------------------------------------------
    def linear(self, k: int) -> bool:
        """Whether contact k is linear in x (a plane): its root under constant acceleration is
        a quadratic's (engine.ode.events)."""
        return self.kinds[k] == PLANE

    def stops(self, k: int) -> bool:
        """Whether touching collider k ends the point's motion (``kill``)."""
        return self.kills[k]

    @ti.func
    def contact(self, k: ti.template(), x, xd, lag):
        """(g, dg/dt, N) of collider k for a point at x moving at xd, ``lag`` seconds before the
        step's end: the signed distance from the surface (m, negative inside), its rate (m/s, the
        collider's own motion included) and the outward unit normal there."""
        p = self.collider_point[k] - self.collider_vel[k] * lag
        N = ti.Vector([0.0, 1.0, 0.0], dt=self.dtype)
        g = ti.cast(0.0, self.dtype)
        if ti.static(self.kinds[k] == PLANE):
            N = self.collider_normal[k]
            g = (x - p).dot(N)
        else:
            d = x - p
            dist = d.norm()
            if dist > 1e-12:
                N = d / dist
            g = dist - self.collider_radius[k]
        return g, (xd - self.collider_vel[k]).dot(N), N

    @ti.func
    def respond(self, k: ti.template(), x, v, lag, dv):
        """Put x on collider k's surface (as placed ``lag`` s before the step's end) and respond:
        restitution and friction on the velocity relative to the collider, or rest (module
        docstring) when e·|v_n| ≤ −N·dv (``dv``: the step's velocity change; zero at a located
        impact, which always bounces). Returns (x', v', impact speed −N·v_r ≥ 0, normal N)."""
        g, _gd, N = self.contact(k, x, v, lag)
        x = x - g * N
        vr = v - self.collider_vel[k]
        vn_s = vr.dot(N)
        speed = ti.max(-vn_s, 0.0)
        if vn_s < 0.0:
            e = self.collider_restitution[k]
            if e * speed <= ti.max(-N.dot(dv), 0.0):
                e = ti.cast(0.0, self.dtype)  # rests: held on the surface
            vn = vn_s * N
            vt = vr - vn
            vt_len = vt.norm()
            scale = ti.cast(0.0, self.dtype)
            if vt_len > 1e-12:
                scale = ti.max(0.0, 1.0 - self.collider_friction[k] * (1.0 + e) * speed / vt_len)
            v = scale * vt - e * vn + self.collider_vel[k]
        return x, v, speed, N

    @ti.func
    def project(self, x, v, x0, v0, h):
        """Every collider in turn: a point that ended the step of h (from x0, v0) inside is put
        back on the surface and responds; if it started the step touching that collider (within
        the rounding band) it may rest (:meth:`respond` with the step's velocity change), so
        contact at rest is held while a point arriving from outside always bounces. Returns (x',
        v', hits, killed, last collider touched (−1: none), its normal, the impact speed there)."""
        killed, hits, which = 0, 0, -1
        n_hit = ti.Vector([0.0, 1.0, 0.0], dt=self.dtype)
        speed = ti.cast(0.0, self.dtype)
        zero = ti.Vector.zero(self.dtype, 3)
        for k in ti.static(range(self.count)):
            g, _gd, _N = self.contact(k, x, v, 0.0)
            if g < 0.0:
                hits += 1
                if ti.static(self.kills[k]):
                    killed = 1
                g0, _gd0, _N0 = self.contact(k, x0, v0, h)
                dv = v - v0 if g0 <= self._band(x0) else zero
                x, v, speed, n_hit = self.respond(k, x, v, 0.0, dv)
                which = k
        return x, v, hits, killed, which, n_hit, speed

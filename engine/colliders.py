"""The shape table: planes, spheres, boxes and capsules, static, moving or spinning, shared by
particles, spring nodes and (publishing their poses into it) rigid bodies.

The table is an *event set* for the ODE core's event location (:mod:`engine.ode.events`): its
contact function g is the signed distance from a shape's surface (negative inside;
:mod:`engine.geometry.shapes`), g = (x − p)·N for a plane and |x − c| − R for a sphere (NUMERICS.md,
"Collisions"), evaluated against where the shape is at the same time. A shape's pose moves over a
step with constant linear velocity v and angular velocity ω (world frame): at ``lag`` seconds
before the step's end it is at p₁ − v·lag, turned back by the rotation vector −ω·lag
(Rodrigues, :func:`~engine.geometry.shapes.rotate`), and the surface point at x moves at
v + ω × (x − p). Its rate ġ = (ẋ − v − ω × (x − p))·N.

Response (Witkin & Baraff, *Particle System Dynamics*; NUMERICS.md), in the frame of the surface
point so a moving or spinning shape pushes and drags what it hits: with v_s = v + ω × r the surface
point's velocity, v_r = v − v_s, v_n = (N·v_r)N, v_t = v_r − v_n, v_r' = v_t' − e v_n with
Coulomb-style friction v_t' = max(0, 1 − μ(1 + e)|v_n|/|v_t|) v_t; the point is put on the
surface. Energy (in the surface point's frame) never grows for e ≤ 1.

Held (resting) contact: a point that ends a step inside a shape is projected back
(:meth:`Colliders.project`); if it started the step touching that shape and its rebound e|v_n|
would be no more than what the step's own acceleration takes out of it (−N·Δv over the step: the
rebound would land within about two steps) it rests — v_n' = 0, friction with e = 0 — so a
particle lying on the ground is held there, not bounced and re-detected at every step (the end
of a bouncing ball's Zeno series).

One table per scene: the particles read it as it is; a soft body reads it through a
:class:`~engine.collider_view.ColliderView` whose compile-time ``offset`` (the body's thickness) is subtracted from every
signed distance — its nodes keep that distance from every surface — sharing the table's fields,
so a moving shape is written once. The set of shapes is fixed when a scene is finalised: their
count, kinds and whether each spins are compile-time constants and the per-shape loop is unrolled
with ``ti.static``, so a scene with no colliders compiles no collision code, one without boxes no
box code, and a shape that does not spin the same arithmetic as before shapes could spin. Poses
live in fields, set from the scene's Control (engine.control) before each step: moving or turning
one costs no recompilation (the writing of poses, and the host's copy of them:
:mod:`engine.collider_poses`).

Rigid bodies' boxes and capsules are the exception: they sit at the table's end as *projected*
shapes, met by the end-of-step projection only (:meth:`Colliders.project`: a point that ends a
step inside one is put on its surface and responds to it, the surface point's v + ω × r
included), through one loop over them that runs at run time, not one unrolled copy per shape. A
body's box inlined at every site of the located step (about eleven per shape, each spinning)
cost minutes of compilation for a stack of ten crates; the loop costs one copy whatever the
count, and a bounding-sphere test per shape. The price: their impacts are not located in time
inside a step (a point moving more than a shape's thickness in one step could pass through).
(Their distance and the run-time loop: :mod:`engine.collider_projected`.)
"""
# (no __future__ annotations: Taichi reads the funcs' ti.template() annotations)

from dataclasses import dataclass, field
from typing import List, Sequence

import numpy as np
import taichi as ti

from .collider_poses import IDENTITY, ShapePoses
from .collider_projected import ProjectedShapes
from .fieldio import ColumnWriter
from .geometry.shapes import (BOX, CAPSULE, KINDS, PLANE, SPHERE, box_local, quat_normalize, rotate,
                              spun, turn, turned)
from .launch import data_oriented
from .ode.events import contact_band

__all__ = ["ColliderSpec", "Colliders", "PLANE", "SPHERE", "BOX", "CAPSULE", "KINDS", "OWNERS"]
OWNERS = ("collider", "rigid")  # who a shape belongs to: a config's collider, or a rigid body's shape


@dataclass
class ColliderSpec:
    """One shape. ``kind`` is "plane" (point, normal), "sphere" (centre = point, radius), "box"
    (centre = point, ``half_extents`` along its body axes) or "capsule" (centre = point, radius,
    ``half_length`` of its segment along the body y axis). ``orientation``: unit quaternion
    [w, x, y, z] turning the body axes (a plane's normal, the capsule's axis) into the world;
    ``angular_velocity``: rad/s, world frame, about ``point``. ``rotates``: compile the spinning
    code even while ω is zero (a pose set from code or by a rigid body); a shape with a nonzero
    ``angular_velocity`` rotates anyway. ``path``: optional (time, position) keyframes moving
    ``point``. ``owner``: "collider" or "rigid" (what a contact names the shape as);
    ``owner_index``: the rigid body's index (−1: none)."""

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
    half_extents: Sequence[float] = (0.5, 0.5, 0.5)
    half_length: float = 0.5
    orientation: Sequence[float] = IDENTITY
    angular_velocity: Sequence[float] = (0.0, 0.0, 0.0)
    rotates: bool = False
    owner: str = "collider"
    owner_index: int = -1

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind: unknown shape {self.kind!r}; allowed: {', '.join(KINDS)}")
        if self.owner not in OWNERS:
            raise ValueError(f"owner: unknown value {self.owner!r}; allowed: {', '.join(OWNERS)}")

    @property
    def spins(self) -> bool:
        """Whether the spinning code is compiled for this shape (a compile-time switch)."""
        return bool(self.rotates) or any(float(c) != 0.0 for c in self.angular_velocity)

    def position_at(self, t: float) -> np.ndarray:
        from .paths import sample_path

        return sample_path(self.path, t, self.point)

    def orientation_at(self, t: float) -> np.ndarray:
        """The orientation at time t: ``orientation`` spun at ``angular_velocity`` since t = 0."""
        q = quat_normalize(self.orientation)
        return spun(q, self.angular_velocity, t) if any(float(c) != 0.0 for c in self.angular_velocity) else q


@data_oriented
class Colliders(ShapePoses, ProjectedShapes):
    """Fields for a fixed list of shapes and the ``ti.func`` s that find and resolve contacts.

    Fields (shape (count,), ``dtype``: f32 for scenes, f64 for reference runs): ``collider_point``
    (plane point or shape centre at the end of the current step, m), ``collider_normal`` (unit,
    world: a plane's normal, a capsule's axis, a box's y axis), ``collider_radius`` (m: sphere, capsule),
    ``collider_vel`` (m/s over the current step), ``collider_restitution``, ``collider_friction``;
    where a scene has such shapes, ``collider_half`` (m: a box's half extents, a capsule's half
    length in y), ``collider_axis_x``, ``collider_axis_z`` (a box's body axes in world; its y axis
    is ``collider_normal``) and
    ``collider_omega`` (rad/s: spinning shapes). ``count``, ``kinds``, ``spins``, ``kills`` and
    ``offset`` (m, subtracted from every signed distance: 0 here, a soft body's thickness in a
    :class:`~engine.collider_view.ColliderView`) are compile-time constants of the kernels.
    """

    offset = 0.0
    # two-way coupling (engine.particles.push.Pusher): set by a particle system whose emitters
    # push rigid bodies, before its kernels compile; a view (soft bodies) never has one
    pusher = None

    def __init__(self, specs: Sequence[ColliderSpec], dtype=ti.f32, writes=None):
        """``writes``: a :class:`~engine.fieldio.WriterGroup` (a scene's) whose one kernel writes
        the shapes' fixed numbers with the other systems' parameters; none: a launch of its own."""
        self.specs = list(specs)
        self.count = len(self.specs)
        self.dtype = dtype
        self.kinds = tuple(KINDS.index(s.kind) for s in self.specs)
        self.spins = tuple(s.spins for s in self.specs)
        self.kills = tuple(bool(s.kill) for s in self.specs)
        self.rotating = any(self.spins)
        # rigid bodies' boxes and capsules: the projected shapes, at the table's end (module docstring)
        projected = [k for k, s in enumerate(self.specs) if s.owner == "rigid" and s.kind in ("box", "capsule")]
        self.event_count = self.count - len(projected)  # the shapes whose impacts are located
        if projected != list(range(self.event_count, self.count)):
            raise ValueError("colliders: rigid bodies' boxes and capsules must come last in the shape table")
        if projected and not all(self.spins[k] for k in projected):
            raise ValueError("colliders: a rigid body's box or capsule must be built to rotate (rotates = true)")
        self.names = tuple(s.name for s in self.specs)
        self.owners = tuple(s.owner for s in self.specs)
        # what a contact names each shape as: (kind, index) — a config's collider by its own
        # index, a rigid body's shape by the body's
        self.parties = tuple((s.owner, s.owner_index if s.owner_index >= 0 else k) for k, s in enumerate(self.specs))
        n = max(1, self.count)
        self.collider_point = ti.Vector.field(3, dtype, shape=n)
        self.collider_normal = ti.Vector.field(3, dtype, shape=n)
        self.collider_radius = ti.field(dtype, shape=n)
        self.collider_vel = ti.Vector.field(3, dtype, shape=n)
        self.collider_restitution = ti.field(dtype, shape=n)
        self.collider_friction = ti.field(dtype, shape=n)
        # the fields of the features in use only (a scene pays for what it has)
        if any(k in (BOX, CAPSULE) for k in self.kinds):
            self.collider_half = ti.Vector.field(3, dtype, shape=n)
        if BOX in self.kinds:  # a box's x and z axes (its y axis is in collider_normal)
            self.collider_axis_x = ti.Vector.field(3, dtype, shape=n)
            self.collider_axis_z = ti.Vector.field(3, dtype, shape=n)
        if self.rotating:
            self.collider_omega = ti.Vector.field(3, dtype, shape=n)
        if self.event_count < self.count:  # projected shapes: their kind and bounding radius (m)
            self.collider_kind = ti.field(ti.i32, shape=n)
            self.collider_bound = ti.field(dtype, shape=n)
        self._np = np.float64 if dtype == ti.f64 else np.float32
        self._pos = np.zeros((n, 3), self._np)
        self._quat = np.zeros((n, 4))
        self._omega = np.zeros((n, 3))
        self._turned = False
        # the shapes' fixed numbers and first positions: one launch for the float fields (a field
        # written element by element from Python compiles an accessor each, ~4-12 ms at a start)
        half, bound, kind = np.zeros((n, 3)), np.zeros(n), np.zeros(n, np.int32)
        for k, s in enumerate(self.specs):
            if self.kinds[k] == BOX:
                half[k] = [float(c) for c in s.half_extents]
            elif self.kinds[k] == CAPSULE:
                half[k] = [0.0, float(s.half_length), 0.0]
            if k >= self.event_count:
                kind[k] = self.kinds[k]
                bound[k] = (float(np.linalg.norm(s.half_extents)) if self.kinds[k] == BOX
                            else float(s.half_length) + float(s.radius))
            self._pos[k] = s.position_at(0.0)
        fixed = [(self.collider_point, self._pos)] + [
            (f, np.array([float(getattr(s, a)) for s in self.specs] or [0.0]))
            for f, a in ((self.collider_radius, "radius"), (self.collider_restitution, "restitution"),
                         (self.collider_friction, "friction"))]
        if hasattr(self, "collider_half"):
            fixed.append((self.collider_half, half))
        if self.event_count < self.count:
            fixed.append((self.collider_bound, bound))
            self.collider_kind.from_numpy(kind)
        self._orient_keys = [None] * self.count  # what each shape's row below was made from
        self._orient_rows = rows = np.zeros((max(1, self.count), 12))
        self._orient([s.orientation_at(0.0) for s in self.specs], [s.angular_velocity for s in self.specs])
        # the first orientations (normal, box axes, ω) in the same launch: the pose kernel
        # (engine.collider_poses) then loads only in a scene whose shapes move or turn
        fixed.append((self.collider_normal, rows[:, 0:3]))
        if BOX in self.kinds:
            fixed += [(self.collider_axis_x, rows[:, 3:6]), (self.collider_axis_z, rows[:, 6:9])]
        if self.rotating:
            fixed.append((self.collider_omega, rows[:, 9:12]))
        ColumnWriter([f for f, _ in fixed], dtype, writes).write(*[a for _, a in fixed])
        self._t = 0.0
        self._band = contact_band(dtype)
        self._moved = False

    def index(self, name: str) -> int:
        for k, s in enumerate(self.specs):
            if s.name == name:
                return k
        raise KeyError(f"collider: no collider named {name!r} "
                       f"(names: {', '.join(repr(s.name) for s in self.specs if s.name) or 'none'})")

    # -- the event set (engine.ode.events) ---------------------------------------------------------
    def linear(self, k: int) -> bool:
        """Whether contact k is linear in x along a step (a plane that does not spin): its root
        under constant acceleration is a quadratic's (engine.ode.events)."""
        return self.kinds[k] == PLANE and not self.spins[k]

    def stops(self, k: int) -> bool:
        """Whether touching shape k ends the point's motion (``kill``)."""
        return self.kills[k]

    @ti.func
    def contact(self, k: ti.template(), x, xd, lag):
        """(g, dg/dt, N) of shape k for a point at x moving at xd, ``lag`` seconds before the
        step's end: the signed distance from the surface less ``offset`` (m, negative inside), its
        rate (m/s, the shape's own motion and spin included) and the outward unit normal there."""
        p = self.collider_point[k] - self.collider_vel[k] * lag
        N = ti.Vector([0.0, 1.0, 0.0], dt=self.dtype)
        g = ti.cast(0.0, self.dtype)
        vs = self.collider_vel[k]  # the velocity of the surface point under x
        kind, spin, d = ti.static(self.kinds[k], self.spins[k], self.offset)
        if ti.static(kind == PLANE):
            N = self.collider_normal[k]
            if ti.static(spin):
                N = rotate(N, self.collider_omega[k], -lag)
            g = (x - p).dot(N)
            if ti.static(d != 0.0):
                g -= d
        elif ti.static(kind == SPHERE):
            dd = x - p
            dist = dd.norm()
            if dist > 1e-12:
                N = dd / dist
            if ti.static(d != 0.0):  # R + d rounded once, as a copy of the table thickened by d held it
                g = dist - ti.static(self.specs[k].radius + d)
            else:
                g = dist - self.collider_radius[k]
        elif ti.static(kind == BOX):
            # against the axes at the step's end, the point turned forward by ω·lag (R(t)ᵀ r =
            # R₁ᵀ Rot(ω·lag) r), the normal turned back by the same rotation
            r = x - p
            ex, ey, ez = self.collider_axis_x[k], self.collider_normal[k], self.collider_axis_z[k]
            if ti.static(spin):
                ax, c, sn = turn(self.collider_omega[k], lag)
                gl, nw = box_local(turned(r, ax, c, sn), ex, ey, ez, self.collider_half[k])
                N = turned(nw, ax, c, -sn)
                g = gl - d
            else:
                g, N = box_local(r, ex, ey, ez, self.collider_half[k])
                if ti.static(d != 0.0):
                    g -= d
        else:  # capsule: the segment p ± L a, a = the body y axis at that time
            a = self.collider_normal[k]
            if ti.static(spin):
                a = rotate(a, self.collider_omega[k], -lag)
            r = x - p
            half = self.collider_half[k][1]
            dd = r - ti.min(ti.max(r.dot(a), -half), half) * a
            dist = dd.norm()
            if dist > 1e-12:
                N = dd / dist
            g = dist - (self.collider_radius[k] + d)
        if ti.static(spin):
            vs = vs + self.collider_omega[k].cross(x - p)
        return g, (xd - vs).dot(N), N

    @ti.func
    def surface_velocity(self, k: ti.template(), x, lag):
        """The velocity (m/s) of shape k's material point at x, ``lag`` s before the step's end:
        v + ω × (x − p) (v alone for a shape that does not spin: the same arithmetic as before
        shapes could spin)."""
        vs = self.collider_vel[k]
        if ti.static(self.spins[k]):
            vs = vs + self.collider_omega[k].cross(x - (self.collider_point[k] - self.collider_vel[k] * lag))
        return vs

    @ti.func
    def respond(self, k: ti.template(), x, v, lag, dv):
        """Put x on shape k's surface (as placed ``lag`` s before the step's end; ``offset`` from
        it) and respond: restitution and friction on the velocity relative to the surface point,
        or rest (module docstring) when e·|v_n| ≤ −N·dv (``dv``: the step's velocity change; zero
        at a located impact, which always bounces). Returns (x', v', impact speed −N·v_r ≥ 0,
        normal N)."""
        g, _gd, N = self.contact(k, x, v, lag)
        return self._reflect(k, x, v, lag, dv, g, N)

    @ti.func
    def _reflect(self, k: ti.template(), x, v, lag, dv, g, N):
        """:meth:`respond` given shape k's (g, N) at x (a caller that has them saves inlining the
        contact function once more: a box's is long)."""
        x = x - g * N
        vc = self.surface_velocity(k, x, lag)
        return self._bounce(x, v, vc, self.collider_restitution[k], self.collider_friction[k], dv, N)

    @ti.func
    def _bounce(self, x, v, vc, e_in, mu, dv, N):
        """The response of a point at x (on the surface) moving at v against a surface point
        moving at vc, restitution e_in and friction mu (module docstring): (x, v', impact speed, N)."""
        vr = v - vc
        vn_s = vr.dot(N)
        speed = ti.max(-vn_s, 0.0)
        if vn_s < 0.0:
            e = e_in
            if e * speed <= ti.max(-N.dot(dv), 0.0):
                e = ti.cast(0.0, self.dtype)  # rests: held on the surface
            vn = vn_s * N
            vt = vr - vn
            vt_len = vt.norm()
            scale = ti.cast(0.0, self.dtype)
            if vt_len > 1e-12:
                scale = ti.max(0.0, 1.0 - mu * (1.0 + e) * speed / vt_len)
            v = scale * vt - e * vn + vc
        return x, v, speed, N

    @ti.func
    def hold(self, k: ti.template(), x, v, dv, g, N):
        """:meth:`project`'s response to shape k alone (not spinning) given its (g, N) at x:
        (x on the surface, v'), :meth:`_bounce`'s values by selects, no branches, so neighbouring
        points' responses vectorise (engine.ode.lanes.settled). (_bounce in this form moved
        debris' and explosion's frames by rounding: it keeps its branches.)"""
        vc, e, mu = self.collider_vel[k], self.collider_restitution[k], self.collider_friction[k]
        vr = v - vc
        vn_s = vr.dot(N)
        speed = ti.max(-vn_s, 0.0)
        e = ti.select(e * speed <= ti.max(-N.dot(dv), 0.0), ti.cast(0.0, self.dtype), e)
        vt = vr - vn_s * N
        vt_len = vt.norm()
        scale = ti.select(vt_len > 1e-12, ti.max(0.0, 1.0 - mu * (1.0 + e) * speed / ti.max(vt_len, 1e-12)), 0.0)
        return x - g * N, ti.select(vn_s < 0.0, scale * vt - e * (vn_s * N) + vc, v)

    @ti.func
    def project(self, x, v, x0, v0, h):
        """Every shape in turn: a point that ended the step of h (from x0, v0) inside is put
        back on the surface and responds; if it started the step touching that shape (within
        the rounding band) it may rest (:meth:`respond` with the step's velocity change), so
        contact at rest is held while a point arriving from outside always bounces. Returns (x',
        v', hits, killed, last shape touched (−1: none), its normal, the impact speed there)."""
        return self.project_for(x, v, x0, v0, h, -1)

    def pushes_on(self, k) -> bool:
        """Whether a response against shape k is recorded for two-way coupling: a pusher is set
        and k is a rigid body's shape (k None: the projected shapes, all of them bodies')."""
        return self.pusher is not None and (k is None or self.owners[k] == "rigid")

    @ti.func
    def push_event(self, k: ti.template(), i, x, dv, lag):
        """Particle slot i changed velocity by ``dv`` (m/s) meeting shape k at x, ``lag`` s
        before the step's end: recorded for the body owning k (``pusher``, two-way coupling;
        nothing is compiled without one or for a config's collider)."""
        if ti.static(self.pushes_on(k)):
            p = self.collider_point[k] - self.collider_vel[k] * lag  # the body's centre then
            self.pusher.add(i, ti.static(self.specs[k].owner_index), x - p, dv)

    @ti.func
    def project_for(self, x, v, x0, v0, h, i):
        """:meth:`project` for particle slot i (−1: none): with a ``pusher`` (two-way coupling,
        engine.particles.push) each response against a rigid body's shape is recorded for slot
        i as the velocity change it gave and its moment about the body's centre."""
        killed, hits, which = 0, 0, -1
        n_hit = ti.Vector([0.0, 1.0, 0.0], dt=self.dtype)
        speed = ti.cast(0.0, self.dtype)
        zero = ti.Vector.zero(self.dtype, 3)
        for k in ti.static(range(self.count)):
            g, _gd, N = self.contact(k, x, v, 0.0)
            if g < 0.0:
                hits += 1
                if ti.static(self.kills[k]):
                    killed = 1
                g0, _gd0, _N0 = self.contact(k, x0, v0, h)
                dv = v - v0 if g0 <= self._band(x0) else zero
                v_in = v
                x, v, speed, n_hit = self._reflect(k, x, v, 0.0, dv, g, N)
                self.push_event(k, i, x, v - v_in, 0.0)
                which = k
        if ti.static(self.event_count < self.count):
            x, v, hits, which, n_hit, speed = self.project_projected(x, v, x0, v0, h, i, hits, which, n_hit, speed)
        return x, v, hits, killed, which, n_hit, speed


"""Plane and sphere colliders, static or moving, shared by particles and spring nodes.

Response (Witkin & Baraff, *Particle System Dynamics*; NUMERICS.md), in the collider's frame so a
moving collider pushes what it hits: with v_r = v − v_c, contact when the point is behind the
surface and N·v_r < 0; v_n = (N·v_r)N, v_t = v_r − v_n, v_r' = v_t' − e v_n with Coulomb-style
friction v_t' = max(0, 1 − μ(1 + e)|v_n|/|v_t|) v_t; then the point is projected back onto the
surface. Energy (in the collider's frame) never grows for e ≤ 1.

The set of colliders is fixed when a scene is finalised: their count is a compile-time constant
and the per-collider loop is unrolled with ``ti.static``, so a scene with no colliders compiles no
collision code. Their positions live in fields, set from the scene's Control
(engine.control) before each step: moving one costs no recompilation.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Sequence

import numpy as np
import taichi as ti

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

    def position_at(self, t: float) -> np.ndarray:
        from .paths import sample_path

        return sample_path(self.path, t, self.point)


class Colliders:
    """Fields for a fixed list of colliders and the ``ti.func`` that resolves contacts.

    Fields (shape (count,)): ``collider_point`` (plane point or sphere centre, m),
    ``collider_normal`` (unit, planes), ``collider_radius`` (m), ``collider_vel`` (m/s, inferred
    from motion between updates), ``collider_restitution``, ``collider_friction``.
    ``shift`` (count, 3): an offset added to every position (a soft body keeps its thickness from
    a plane by a copy of it moved along the normal).
    """

    def __init__(self, specs: Sequence[ColliderSpec], shift=None):
        self.specs = list(specs)
        self.count = len(self.specs)
        self.kinds = tuple(PLANE if s.kind == "plane" else SPHERE for s in self.specs)
        self.kills = tuple(bool(s.kill) for s in self.specs)
        n = max(1, self.count)
        self.collider_point = ti.Vector.field(3, ti.f32, shape=n)
        self.collider_normal = ti.Vector.field(3, ti.f32, shape=n)
        self.collider_radius = ti.field(ti.f32, shape=n)
        self.collider_vel = ti.Vector.field(3, ti.f32, shape=n)
        self.collider_restitution = ti.field(ti.f32, shape=n)
        self.collider_friction = ti.field(ti.f32, shape=n)
        self._pos = np.zeros((n, 3), np.float32)
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
        self._moved = False

    def reset(self) -> None:
        """Back where the specs start, at rest, at t = 0 (a reused scene)."""
        if self._moved:
            for k, s in enumerate(self.specs):
                self._pos[k] = s.position_at(0.0) + self.shift[k]
            self.collider_point.from_numpy(self._pos)
            self.collider_vel.from_numpy(np.zeros_like(self._pos))
        self._t, self._moved = 0.0, False

    def move_to(self, t: float, positions=None) -> None:
        """Set the colliders' positions for time t (``positions`` (count, 3), else from their
        specs' paths) and infer their velocities from the motion since the last call."""
        if self.count == 0:
            return
        pos = np.array([s.position_at(t) for s in self.specs] if positions is None else positions,
                       np.float64).reshape(self.count, 3)
        new = (pos + self.shift).astype(np.float32) if self.shift.any() else pos.astype(np.float32)
        dt = t - self._t
        vel = (new - self._pos[: self.count]) / dt if dt > 0 else np.zeros_like(new)
        self._pos[: self.count] = new
        self._t, self._moved = t, True
        self.collider_point.from_numpy(self._pos)
        v = np.zeros_like(self._pos)
        v[: self.count] = vel
        self.collider_vel.from_numpy(v)

    def placement(self) -> bytes:
        """Where the colliders are now, as bytes (normals and radii never change): what a cached
        background depends on. Read from the host copy, so it costs no kernel launch."""
        return self._pos[: self.count].tobytes()

    def index(self, name: str) -> int:
        for k, s in enumerate(self.specs):
            if s.name == name:
                return k
        raise KeyError(f"collider: no collider named {name!r} "
                       f"(names: {', '.join(repr(s.name) for s in self.specs if s.name) or 'none'})")

    def make_func(self, report: bool = False):
        """``collide(x, v) -> (x', v', killed, hits)`` for one point; the per-collider loop is
        unrolled at compile time. ``hits`` counts contacts resolved; ``killed`` is 1 when a
        collider with ``kill`` was touched. With ``report`` it also returns the last contact's
        collider index (−1: none), normal and impact speed −N·v_r (m/s)."""
        kinds, kills, count = self.kinds, self.kills, self.count
        cp, cn, cr = self.collider_point, self.collider_normal, self.collider_radius
        cv, ce, cf = self.collider_vel, self.collider_restitution, self.collider_friction

        @ti.func
        def collide(x, v):
            killed = 0
            hits = 0
            which = -1
            n_hit = ti.Vector([0.0, 0.0, 0.0])
            speed = 0.0
            for k in ti.static(range(count)):
                N = ti.Vector([0.0, 1.0, 0.0])
                depth = 0.0  # signed distance: negative inside
                if ti.static(kinds[k] == PLANE):
                    N = cn[k]
                    depth = (x - cp[k]).dot(N)
                else:
                    d = x - cp[k]
                    dist = d.norm()
                    N = d / ti.max(dist, 1e-12) if dist > 1e-12 else ti.Vector([0.0, 1.0, 0.0])
                    depth = dist - cr[k]
                if depth < 0.0:
                    hits += 1
                    if ti.static(kills[k]):
                        killed = 1
                    x = x - depth * N  # project back onto the surface
                    vr = v - cv[k]
                    vn_s = vr.dot(N)
                    which = k
                    n_hit = N
                    speed = ti.max(0.0, -vn_s)
                    if vn_s < 0.0:
                        vn = vn_s * N
                        vt = vr - vn
                        e = ce[k]
                        vt_len = vt.norm()
                        scale = 0.0
                        if vt_len > 1e-12:
                            scale = ti.max(0.0, 1.0 - cf[k] * (1.0 + e) * ti.abs(vn_s) / vt_len)
                        v = scale * vt - e * vn + cv[k]
            return x, v, killed, hits, which, n_hit, speed

        @ti.func
        def collide4(x, v):
            x2, v2, killed, hits, _which, _normal, _speed = collide(x, v)
            return x2, v2, killed, hits

        return collide if report else collide4

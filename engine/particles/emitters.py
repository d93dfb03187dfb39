"""Emitters: shapes, rates with fractional carry-over, bursts, moving emitters.

Scheduling (how many particles, when) is exact integer bookkeeping in Python, once per emitter per
step; spawning (where, how fast) is one kernel launch per emitter per step that writes ``k`` new
particles into the emitter's ring segment. Every random number is a hash of (seed, emitter, the
particle's serial number): a run is reproducible and independent of thread count.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import math
from dataclasses import dataclass, field
from typing import List

import numpy as np
import taichi as ti

from ..paths import sample_path
from .rng import rand01

SHAPES = {"point": 0, "sphere": 1, "box": 2, "disc": 3, "cone": 4}
TWO_PI = 2.0 * math.pi


@dataclass
class EmitterClock:
    """Python-side emission bookkeeping of one emitter (State, not Model)."""

    rate: float
    start: float
    stop: float
    bursts: List[tuple]  # (time, count), every cycle expanded, sorted
    carry: float = 0.0
    serial: int = 0
    head: int = 0
    next_burst: int = 0
    emitted: int = 0
    enabled: bool = True
    pending: List[int] = field(default_factory=list)  # counts of bursts triggered at runtime

    def schedule(self, t0: float, t1: float):
        """Spawns for [t0, t1): a list of (count, spawn-time start, spawn-time span)."""
        out = []
        a, b = max(t0, self.start), min(t1, self.stop)
        if self.enabled and self.rate > 0 and b > a:
            exact = self.rate * (b - a) + self.carry
            k = int(math.floor(exact))
            self.carry = exact - k
            if k:
                out.append((k, a, b - a))
        while self.next_burst < len(self.bursts) and self.bursts[self.next_burst][0] < t1:
            tb, count = self.bursts[self.next_burst]
            self.next_burst += 1
            out.append((count, max(tb, t0), 0.0))
        for count in self.pending:
            out.append((count, t0, 0.0))
        self.pending.clear()
        return out


class Emitters:
    """Per-emitter parameters as fields (shape (E,)), their clocks, and the spawn kernel."""

    def __init__(self, configs, layout, state, seed: int):
        self.configs = list(configs)
        self.layout, self.state, self.seed = layout, state, int(seed)
        E = len(self.configs)
        self.count = E
        f = lambda: ti.field(ti.f32, shape=E)  # noqa: E731
        self.emitter_shape = ti.field(ti.i32, shape=E)
        self.emitter_surface = ti.field(ti.i32, shape=E)
        self.emitter_radius, self.emitter_cos_spread = f(), f()
        self.emitter_speed_min, self.emitter_speed_max = f(), f()
        self.emitter_inherit, self.emitter_life, self.emitter_life_rand = f(), f(), f()
        self.emitter_drag = f()
        self.emitter_box = ti.Vector.field(3, ti.f32, shape=E)
        self.emitter_dir = ti.Vector.field(3, ti.f32, shape=E)
        self.clocks = []
        for e, c in enumerate(self.configs):
            self.emitter_shape[e] = SHAPES[c.shape]
            self.emitter_surface[e] = int(c.surface)
            self.emitter_radius[e] = c.radius
            self.emitter_cos_spread[e] = math.cos(math.radians(c.spread))
            self.emitter_speed_min[e], self.emitter_speed_max[e] = c.speed
            self.emitter_inherit[e] = c.inherit_velocity
            self.emitter_life[e] = c.lifetime
            self.emitter_life_rand[e] = c.lifetime_randomness
            self.emitter_drag[e] = -1.0 if c.drag is None else c.drag  # −1: use the scene's drag
            self.emitter_box[e] = c.box_size
            d = np.asarray(c.direction, np.float64)
            self.emitter_dir[e] = (d / np.linalg.norm(d)).tolist()
            bursts = sorted((b.time + j * b.interval, b.count) for b in c.bursts for j in range(b.cycles))
            self.clocks.append(EmitterClock(c.rate, c.start, math.inf if c.stop is None else c.stop,
                                            bursts))
        self.dropped = ti.field(ti.i32, shape=max(1, E))
        self.positions = [np.asarray(sample_path(c.path, 0.0, c.position), np.float64)
                          for c in self.configs]
        self._spawn = None

    def position_at(self, e: int, t: float) -> np.ndarray:
        c = self.configs[e]
        return np.asarray(sample_path(c.path, t, c.position), np.float64) if c.path else self.positions[e]

    def build(self, birth):
        """Compile the spawn kernel. ``birth(i, t, h)`` is the integrator's single-particle step:
        a particle born at t_s inside a step [t0, t1) is advanced to t1 by one step of the scene's
        own method with h = t1 − t_s, so it feels the forces (and colliders) from its birth on —
        a ballistic start would leave an O(h) velocity error that never decays."""
        S = self.state
        pos, vel, age, life, alive = (S.particle_pos, S.particle_vel, S.particle_age,
                                      S.particle_life, S.particle_alive)
        pem, prand = S.particle_emitter, S.particle_rand
        shape, surface, radius, box, edir = (self.emitter_shape, self.emitter_surface,
                                             self.emitter_radius, self.emitter_box, self.emitter_dir)
        cos_spread, smin, smax = self.emitter_cos_spread, self.emitter_speed_min, self.emitter_speed_max
        inherit, elife, elrand, dropped = (self.emitter_inherit, self.emitter_life,
                                           self.emitter_life_rand, self.dropped)
        seed = self.seed
        vec3 = ti.types.vector(3, ti.f32)

        @ti.func
        def basis(n):
            """Two unit vectors orthogonal to unit n (Frisvad-style branch on the larger axis)."""
            a = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(n[0]) < 0.9 else ti.Vector([0.0, 1.0, 0.0])
            u = n.cross(a).normalized()
            return u, n.cross(u)

        @ti.kernel
        def spawn(e: ti.i32, k: ti.i32, serial0: ti.i32, head: ti.i32, seg_start: ti.i32,
                  seg_size: ti.i32, t_end: ti.f32, ts0: ti.f32, tspan: ti.f32,
                  pa: vec3, pb: vec3, t0: ti.f32, h: ti.f32, ev: vec3):
            for j in range(k):
                slot = seg_start + (head + j) % seg_size
                if alive[slot] != 0:
                    ti.atomic_add(dropped[e], 1)  # the ring caught up with a live particle
                else:
                    sid = serial0 + j
                    r = ti.Vector([rand01(seed, e, sid, q) for q in ti.static(range(8))])
                    ts = ts0 + tspan * (ti.cast(j, ti.f32) + r[0]) / ti.cast(k, ti.f32)
                    a = 0.0
                    if h > 0:
                        a = ti.min(1.0, ti.max(0.0, (ts - t0) / h))
                    centre = pa + a * (pb - pa)
                    n = edir[e]
                    u, w = basis(n)
                    off = ti.Vector([0.0, 0.0, 0.0])
                    d = n
                    sh = shape[e]
                    if sh == 1:  # sphere: volume or surface
                        z = 2.0 * r[1] - 1.0
                        phi = TWO_PI * r[2]
                        s = ti.sqrt(ti.max(0.0, 1.0 - z * z))
                        rr = radius[e] * (1.0 if surface[e] != 0 else ti.pow(r[3], 1.0 / 3.0))
                        off = rr * ti.Vector([s * ti.cos(phi), s * ti.sin(phi), z])
                    elif sh == 2:  # box
                        off = (ti.Vector([r[1], r[2], r[3]]) - 0.5) * box[e]
                    elif sh == 3 or sh == 4:  # disc (and the cone's base), perpendicular to n
                        rr = radius[e] * ti.sqrt(r[1])
                        phi = TWO_PI * r[2]
                        radial = ti.cos(phi) * u + ti.sin(phi) * w
                        off = rr * radial
                        if sh == 4 and radius[e] > 0:  # cone: tilt outward with the offset
                            tilt = ti.acos(cos_spread[e]) * rr / radius[e]
                            d = ti.cos(tilt) * n + ti.sin(tilt) * radial
                    # direction inside a cone of half-angle `spread` around d (uniform on the cap)
                    dd = d
                    if sh != 4:
                        cz = 1.0 - r[4] * (1.0 - cos_spread[e])
                        sz = ti.sqrt(ti.max(0.0, 1.0 - cz * cz))
                        phi2 = TWO_PI * r[5]
                        du, dw = basis(d)
                        dd = cz * d + sz * (ti.cos(phi2) * du + ti.sin(phi2) * dw)
                    speed = smin[e] + (smax[e] - smin[e]) * r[6]
                    v = speed * dd + inherit[e] * ev
                    pos[slot] = centre + off
                    vel[slot] = v
                    age[slot] = 0.0
                    life[slot] = elife[e] * (1.0 - elrand[e] * r[7])
                    alive[slot] = 1
                    pem[slot] = e
                    prand[slot] = rand01(seed, e, sid, 9)
                    if t_end - ts > 0:
                        birth(slot, ts, t_end - ts)

        self._spawn = spawn

    def emit(self, t0: float, h: float) -> int:
        """Spawn everything due in [t0, t0 + h), each advanced from its birth time to t0 + h.
        Call after the step [t0, t0 + h) was taken (accepted). Returns the number spawned."""
        total = 0
        t1 = t0 + h
        for e, clock in enumerate(self.clocks):
            plan = clock.schedule(t0, t1)
            if not plan:
                continue
            pa, pb = self.position_at(e, t0), self.position_at(e, t1)
            ev = (pb - pa) / h if h > 0 else np.zeros(3)
            start, size = self.layout.starts[e], self.layout.sizes[e]
            for k, ts0, tspan in plan:
                if k > size:  # more than the whole ring at once: the excess can never fit
                    self.dropped[e] += k - size
                    clock.serial += k - size
                    k = size
                self._spawn(e, k, clock.serial, clock.head, start, size, t1, ts0, tspan,
                            pa.tolist(), pb.tolist(), t0, h, ev.tolist())
                clock.serial += k
                clock.head = (clock.head + k) % size
                clock.emitted += k
                total += k
        return total

    def dropped_counts(self) -> np.ndarray:
        return self.dropped.to_numpy()[: self.count]

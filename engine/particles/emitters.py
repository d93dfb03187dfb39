"""Emitters: shapes, rates with fractional carry-over, bursts, moving emitters, sub-emitters.

Scheduling (how many particles, when) is exact bookkeeping in Python, once per emitter per step;
spawning (where, how fast) is one kernel launch per emitter per step that writes ``k`` new
particles at the emitter's ring head. Every random number is a hash of (seed, emitter, the
particle's serial number): a run is reproducible and independent of thread count.

Sub-emitters (a flame that leaves smoke when it dies, a spark that throws smaller sparks when it
hits the ground) read event flags the step kernel sets, in one serial pass over the parent's
segment: children get their slots in parent-slot order, so the result is deterministic.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)
import math
from dataclasses import dataclass
from typing import List

import numpy as np
import taichi as ti

from ..paths import sample_path
from .rng import rand01

SHAPES = {"point": 0, "sphere": 1, "box": 2, "disc": 3, "cone": 4}
TWO_PI = 2.0 * math.pi
EVENT_DEATH, EVENT_COLLISION = 1, 2


@dataclass
class EmitterClock:
    """Python-side emission schedule of one emitter (State, not Model)."""

    rate: float
    start: float
    stop: float
    bursts: List[tuple]  # (time, count), every cycle expanded, sorted
    carry: float = 0.0
    next_burst: int = 0
    enabled: bool = True
    until: float = 0.0  # emission is scheduled up to here (an adaptive step may be retried shorter)

    def schedule(self, t0: float, t1: float, pending=()):
        """Spawns for [t0, t1) not scheduled yet: a list of (count, birth-time start, span)."""
        out = []
        a, b = max(t0, self.until, self.start), min(t1, self.stop)
        self.until = max(self.until, t1)
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
        out += [(count, t0, 0.0) for count in pending]
        return out


class Emitters:
    """Per-emitter parameters as fields (shape (E,)), ring heads and serial counters (fields, so
    kernels and Python share one truth), clocks, and the spawn kernels."""

    def __init__(self, configs, layout, seed: int):
        self.configs = list(configs)
        self.layout, self.seed = layout, int(seed)
        self.state = None  # the pool, given to build()
        E = len(self.configs)
        self.count = E
        self.index = {c.name: e for e, c in enumerate(self.configs) if c.name}
        f = lambda: ti.field(ti.f32, shape=E)  # noqa: E731
        self.emitter_shape = ti.field(ti.i32, shape=E)
        self.emitter_surface = ti.field(ti.i32, shape=E)
        self.emitter_radius, self.emitter_cos_spread = f(), f()
        self.emitter_speed_min, self.emitter_speed_max = f(), f()
        self.emitter_inherit, self.emitter_life, self.emitter_life_rand = f(), f(), f()
        self.emitter_drag = f()
        self.emitter_box = ti.Vector.field(3, ti.f32, shape=E)
        self.emitter_dir = ti.Vector.field(3, ti.f32, shape=E)
        self.emitter_head = ti.field(ti.i32, shape=E)
        self.emitter_serial = ti.field(ti.i32, shape=E)
        self.emitter_emitted = ti.field(ti.i32, shape=E)
        self.dropped = ti.field(ti.i32, shape=E)
        self.clocks, self.pending = [], [[] for _ in range(E)]
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
                                            bursts, enabled=c.emitting))
        # sub-emitter links (parent, child, event bit, count, min speed), fixed at build time
        self.links = [(p, self.index[s.emitter], EVENT_DEATH if s.event == "death" else EVENT_COLLISION,
                       s.count, s.min_speed)
                      for p, c in enumerate(self.configs) for s in c.sub_emitters]
        self.positions = [np.asarray(sample_path([(k.time, k.position) for k in c.path], 0.0, c.position),
                                     np.float64) for c in self.configs]
        self.runtime_paths = {}
        self._spawn = None

    @property
    def uses_events(self) -> bool:
        return bool(self.links)

    def position_at(self, e: int, t: float) -> np.ndarray:
        path = self.runtime_paths.get(e) or self.configs[e].path
        if not path:
            return self.positions[e]
        if isinstance(path[0], tuple):
            return np.asarray(sample_path(path, t, self.positions[e]), np.float64)
        return np.asarray(sample_path([(k.time, k.position) for k in path], t, self.positions[e]), np.float64)

    def set_target(self, e: int, t_now: float, t_next: float, position) -> None:
        """Control: emitter e moves linearly to ``position`` by ``t_next``; particles inherit the
        inferred velocity (``inherit_velocity``) and are spread along the motion."""
        here = tuple(float(c) for c in self.position_at(e, t_now))
        self.runtime_paths[e] = [(t_now, here), (max(t_next, t_now + 1e-9), tuple(float(c) for c in position))]

    def build(self, state):
        """Compile the spawn kernels. A particle born at t_s inside the step [t0, t1) about to be
        taken is written at the emitter's position at t_s with age −(t_s − t0): the step kernel
        then advances it from t_s (see :mod:`engine.particles.integrate`)."""
        self.state = S = state
        pos, vel, age, life, alive = (S.particle_pos, S.particle_vel, S.particle_age,
                                      S.particle_life, S.particle_alive)
        pem, prand = S.particle_emitter, S.particle_rand
        shape, surface, radius, box, edir = (self.emitter_shape, self.emitter_surface,
                                             self.emitter_radius, self.emitter_box, self.emitter_dir)
        cos_spread, smin, smax = self.emitter_cos_spread, self.emitter_speed_min, self.emitter_speed_max
        inherit, elife, elrand, dropped = (self.emitter_inherit, self.emitter_life,
                                           self.emitter_life_rand, self.dropped)
        head, serial, emitted = self.emitter_head, self.emitter_serial, self.emitter_emitted
        seed = self.seed
        vec3 = ti.types.vector(3, ti.f32)

        @ti.func
        def basis(n):
            """Two unit vectors orthogonal to unit n."""
            a = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(n[0]) < 0.9 else ti.Vector([0.0, 1.0, 0.0])
            u = n.cross(a).normalized()
            return u, n.cross(u)

        @ti.func
        def init_particle(slot, e, sid, centre, base_vel):
            """A new particle of emitter e in ``slot``: shape offset around ``centre``, direction
            within the spread, speed in range, plus inherit × base_vel. Returns r[0] (a spare
            uniform number the caller may use)."""
            r = ti.Vector([rand01(seed, e, sid, q) for q in ti.static(range(8))])
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
                if sh == 4 and radius[e] > 0:  # cone: directions tilt outward with the offset
                    tilt = ti.acos(cos_spread[e]) * rr / radius[e]
                    d = ti.cos(tilt) * n + ti.sin(tilt) * radial
            dd = d
            if sh != 4:  # uniform on the spherical cap of half-angle `spread` around d
                cz = 1.0 - r[4] * (1.0 - cos_spread[e])
                sz = ti.sqrt(ti.max(0.0, 1.0 - cz * cz))
                phi2 = TWO_PI * r[5]
                du, dw = basis(d)
                dd = cz * d + sz * (ti.cos(phi2) * du + ti.sin(phi2) * dw)
            speed = smin[e] + (smax[e] - smin[e]) * r[6]
            pos[slot] = centre + off
            vel[slot] = speed * dd + inherit[e] * base_vel
            age[slot] = 0.0
            life[slot] = elife[e] * (1.0 - elrand[e] * r[7])
            alive[slot] = 1
            pem[slot] = e
            prand[slot] = rand01(seed, e, sid, 9)
            return r[0]

        @ti.kernel
        def spawn(e: ti.i32, k: ti.i32, seg_start: ti.i32, seg_size: ti.i32, ts0: ti.f32,
                  tspan: ti.f32, pa: vec3, pb: vec3, t0: ti.f32, h: ti.f32, ev: vec3):
            h0 = head[e]
            s0 = serial[e]
            for j in range(k):
                slot = seg_start + (h0 + j) % seg_size
                if alive[slot] != 0:
                    ti.atomic_add(dropped[e], 1)  # the ring caught up with a live particle
                else:
                    ti.atomic_add(emitted[e], 1)
                    sid = s0 + j
                    # stratified birth times across the step, so a stream has no gaps or clumps
                    jitter = rand01(seed, e, sid, 10)
                    ts = ts0 + tspan * (ti.cast(j, ti.f32) + jitter) / ti.cast(k, ti.f32)
                    a = 0.0
                    if h > 0:
                        a = ti.min(1.0, ti.max(0.0, (ts - t0) / h))
                    init_particle(slot, e, sid, pa + a * (pb - pa), ev)
                    age[slot] = -ti.max(0.0, ts - t0)  # born this long into the step
            head[e] = (h0 + k) % seg_size
            serial[e] = s0 + k

        self._spawn = spawn

        if self.links:
            event, impact = S.particle_event, S.particle_impact

            @ti.kernel
            def sub_spawn(p_start: ti.i32, p_size: ti.i32, c: ti.i32, c_start: ti.i32,
                          c_size: ti.i32, count: ti.i32, bit: ti.i32, min_speed: ti.f32):
                # one serial pass: children take slots in parent-slot order (deterministic)
                ti.loop_config(serialize=True)
                for i in range(p_start, p_start + p_size):
                    fire = (event[i] & bit) != 0
                    if bit == EVENT_COLLISION:
                        fire = fire and impact[i] >= min_speed
                    if fire:
                        for j in range(count):
                            slot = c_start + head[c]
                            head[c] = (head[c] + 1) % c_size
                            if alive[slot] != 0:
                                dropped[c] += 1
                            else:
                                emitted[c] += 1
                                init_particle(slot, c, serial[c], pos[i], vel[i])
                            serial[c] += 1

            @ti.kernel
            def clear_events():
                for i in event:
                    event[i] = 0
                    impact[i] = 0.0

            self._sub_spawn, self._clear_events = sub_spawn, clear_events

    def emit_children(self) -> None:
        """Run every sub-emitter link on the events of the step just taken, then clear them."""
        L = self.layout
        for p, c, bit, count, min_speed in self.links:
            self._sub_spawn(L.starts[p], L.sizes[p], c, L.starts[c], L.sizes[c], count, bit, min_speed)
        if self.links:
            self._clear_events()

    def emit(self, t0: float, h: float) -> None:
        """Write everything due in [t0, t0 + h) before the step [t0, t0 + h) is taken."""
        t1 = t0 + h
        for e, clock in enumerate(self.clocks):
            plan = clock.schedule(t0, t1, self.pending[e])
            self.pending[e].clear()
            if not plan:
                continue
            pa, pb = self.position_at(e, t0), self.position_at(e, t1)
            ev = (pb - pa) / h if h > 0 else np.zeros(3)
            start, size = self.layout.starts[e], self.layout.sizes[e]
            for k, ts0, tspan in plan:
                if k > size:  # more than the whole ring at once: the excess can never fit
                    self.dropped[e] += k - size
                    self.emitter_serial[e] += k - size
                    k = size
                self._spawn(e, k, start, size, ts0, tspan, pa.tolist(), pb.tolist(), t0, h,
                            ev.tolist())

    def burst(self, e: int, count: int) -> None:
        """Queue ``count`` particles from emitter e at the start of the next step."""
        self.pending[e].append(int(count))

    def dropped_counts(self) -> np.ndarray:
        return self.dropped.to_numpy()[: self.count]

    def emitted_counts(self) -> np.ndarray:
        return self.emitter_emitted.to_numpy()[: self.count]

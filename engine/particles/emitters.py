"""Emitters: shapes, rates with fractional carry-over, bursts, moving emitters, sub-emitters.

Scheduling (how many particles, when) is exact bookkeeping in Python, once per emitter per step,
from the emitters' inputs in the scene's Control (rate, emitting, bursts, path); spawning (where,
how fast) is one kernel launch per step for all emitters (:func:`engine.particles.spawn.spawn`)
that writes each emitter's new particles at its ring head. Sub-emitters (a flame that leaves smoke
when it dies, a spark that throws smaller sparks when it hits the ground) read the event flags
the step kernel sets, two parallel passes per link (:mod:`engine.particles.spawn`).
"""
import math
from dataclasses import dataclass
from typing import List

import numpy as np
import taichi as ti

from .. import runtime
from ..fieldio import ColumnWriter, WriterGroup
from ..launch import data_oriented
from . import local_space as _local
from . import spawn as _k
from .spawn import EVENT_COLLISION, EVENT_DEATH, SHAPES

CHUNKS = 256  # most slices a sub-emitter pass splits a parent segment into (pass 2 sums ≤ 256 counts)
CHUNK_MIN = 2048  # ... of at least this many slots each
# a link whose parents are one slice and that can write at most this many children a step (its
# parents × count, or its child segment's size if less) runs its loops on the launching thread
# (engine.particles.spawn.spawn_children: ``serial``; ~0.2 µs a child written there)
SERIAL_CHILDREN = 8192
# a spawn launch of at most this many births runs its loops on the launching thread (``serial``):
# its four loops' hand-offs to the thread pool cost more than the second core saves, as far as
# measured (the bench's step, kernel profiler over 50 steps, the launch's loops summed: 2,083
# births at 1M 0.18-0.20 ms parallel, 0.125 serial; 8,333-8,334 at 4M 0.67-0.75 parallel,
# 0.56-0.57 serial). The limit is the largest count measured to gain, so the 4M step's respawn
# is taken too; 512 before, from 6314f0b, set for launches of a few births.
SERIAL_BIRTHS = 8334


@dataclass
class EmitterClock:
    """Python-side emission schedule of one emitter (State: what has been emitted so far)."""

    start: float
    stop: float
    bursts: List[tuple]  # (time, count), every cycle expanded, sorted
    carry: float = 0.0
    next_burst: int = 0
    until: float = 0.0  # emission is scheduled up to here (an adaptive step may be retried shorter)

    def schedule(self, t0: float, t1: float, inp):
        """Spawns for [t0, t1) not scheduled yet, from the emitter's input ``inp`` (rate,
        emitting, pending bursts): a list of (count, birth-time start, span, position or None:
        at the emitter)."""
        out = []
        a, b = max(t0, self.until, self.start), min(t1, self.stop)
        self.until = max(self.until, t1)
        if inp.emitting and inp.rate > 0 and b > a:
            exact = inp.rate * (b - a) + self.carry
            k = int(math.floor(exact))
            self.carry = exact - k
            if k:
                out.append((k, a, b - a, None))
        while self.next_burst < len(self.bursts) and self.bursts[self.next_burst][0] < t1:
            tb, count = self.bursts[self.next_burst]
            self.next_burst += 1
            out.append((count, max(tb, t0), 0.0, None))
        out += [(count, t0, 0.0, at) for count, at in inp.bursts]
        inp.bursts.clear()
        return out


@data_oriented
class Emitters:
    """Per-emitter parameters as fields (shape (rows,): one row per emitter, spare rows zero),
    ring heads and serial counters (fields, so kernels and Python share one truth) and the
    clocks; ``inputs``: the control's emitter inputs."""

    def __init__(self, configs, layout, seed: int, inputs, state, rows: int = 0, writes=None):
        """``rows``: parameter rows to allocate (at least one per emitter): spare rows let
        emitters be added later (:meth:`set_configs`) without new fields or compiles.
        ``writes``: the :class:`~engine.fieldio.WriterGroup` that writes the parameters and
        counters (the system's, shared with its forces: one kernel), else this object's own."""
        self.layout, self.seed, self.inputs, self.state = layout, int(seed), inputs, state
        self.count = R = max(len(configs), int(rows))  # rows: a compile-time bound of the spawn kernel
        self._params = {}
        arrays = self._arrays(configs)
        for name, (a, dtype) in arrays.items():
            vec = a.ndim == 2
            fld = ti.Vector.field(a.shape[1], dtype, shape=R) if vec else ti.field(dtype, shape=R)
            setattr(self, name, fld)
            self._params[name] = fld
        # the parameters and counters written by one kernel (engine.fieldio), not a from_numpy a field
        self.writes = writes = writes if writes is not None else WriterGroup()
        self._writers = []
        for dt in (ti.f32, ti.i32):
            names = [n for n, (_a, d) in arrays.items() if d == dt]
            if names:
                self._writers.append((names, ColumnWriter([self._params[n] for n in names], dt, writes)))
        # ring heads, serial numbers and counts: state the kernels and Python share
        self.emitter_head, self.emitter_serial = ti.field(ti.i32, shape=R), ti.field(ti.i32, shape=R)
        self.emitter_emitted, self.dropped = ti.field(ti.i32, shape=R), ti.field(ti.i32, shape=R)
        self.emitter_moved = ti.field(ti.i32, shape=R)  # births of a launch whose ring slot was alive
        self.emitter_fit = ti.field(ti.i32, shape=R)  # where the free-slot search goes on (spawn: next fit)
        self._counters = ColumnWriter([self.emitter_head, self.emitter_serial, self.emitter_emitted, self.dropped,
                                       self.emitter_moved, self.emitter_fit], ti.i32, writes)
        with writes.held():
            self.set_configs(configs)
            if R:
                self._zero_counters()
        # sub-emitter links (parent, child, event bit, count, min speed), fixed at build time
        if self.links:
            self.link_counts = ti.field(ti.i32, shape=CHUNKS)
            # the children of one pass by rank (at most a ring): parent slot, and slot (−1: none)
            ring = max(max(layout.sizes[c] for _, c, *_ in self.links), 1)
            self.link_parent, self.link_slot = ti.field(ti.i32, shape=ring), ti.field(ti.i32, shape=ring)

    def _arrays(self, cs) -> dict:
        """name → (array of shape (rows,) or (rows, 3), dtype) of every per-emitter parameter;
        rows past the emitters are zero."""
        def pad(values, dtype=ti.f32):
            a = np.zeros((self.count,) + np.shape(values)[1:], np.float32 if dtype == ti.f32 else np.int32)
            a[: len(values)] = values
            return a, dtype

        direction = np.array([c.direction for c in cs], np.float64).reshape(len(cs), 3)
        return dict(
            emitter_shape=pad([SHAPES[c.shape] for c in cs], ti.i32),
            emitter_surface=pad([int(c.surface) for c in cs], ti.i32),
            emitter_radius=pad([c.radius for c in cs]),
            emitter_cos_spread=pad([math.cos(math.radians(c.spread)) for c in cs]),
            emitter_speed_min=pad([c.speed[0] for c in cs]),
            emitter_speed_max=pad([c.speed[1] for c in cs]),
            emitter_inherit=pad([c.inherit_velocity for c in cs]),
            emitter_life=pad([c.lifetime for c in cs]),
            emitter_life_rand=pad([c.lifetime_randomness for c in cs]),
            emitter_drag=pad([-1.0 if c.drag is None else c.drag for c in cs]),  # −1: the scene's drag
            emitter_box=pad(np.array([c.box_size for c in cs], np.float64).reshape(len(cs), 3)),
            emitter_dir=pad(direction / np.linalg.norm(direction, axis=1, keepdims=True)),
        )

    def set_configs(self, configs) -> None:
        """Write every emitter's parameters (``configs``: the emitters there were, unchanged and
        in order, then any new ones, at most ``count`` in all); new emitters get fresh clocks.
        Writes fields only: nothing is allocated or compiled (after the first call)."""
        cs = self.configs = list(configs)
        if self.count:
            arrays = self._arrays(cs)
            for names, writer in self._writers:
                writer.write(*[arrays[n][0] for n in names])
        self.index = {c.name: e for e, c in enumerate(cs) if c.name}
        kept = getattr(self, "clocks", [])[: len(cs)]
        self.clocks = kept + self._clocks()[len(kept):]
        # local space: live particles carried with the emitter's motion (engine.particles.local_space)
        self.local = [e for e, c in enumerate(cs) if c.space == "local"]
        carried = getattr(self, "_carried", {})
        self._carried = {e: carried.get(e, self.position_at(e, 0.0)) for e in self.local}
        self.links = [(p, self.index[s.emitter], EVENT_DEATH if s.event == "death" else EVENT_COLLISION,
                       s.count, s.min_speed)
                      for p, c in enumerate(cs) for s in c.sub_emitters]

    def _zero_counters(self) -> None:
        self._counters.zero(self.count)

    def _clocks(self):
        return [EmitterClock(c.start, math.inf if c.stop is None else c.stop,
                             sorted((b.time + j * b.interval, b.count) for b in c.bursts for j in range(b.cycles)))
                for c in self.configs]

    def reset(self) -> None:
        """Back to the start: clocks, ring heads, serial numbers and counts (a reused scene)."""
        if self.count:
            self._zero_counters()
        self.clocks = self._clocks()
        self._carried = {e: self.position_at(e, 0.0) for e in self.local}

    def carry_local(self, t0: float, t1: float, compile_only: bool = False) -> None:
        """Move the particles of local-space emitters with their emitter over [t0, t1]: by the
        motion within the span (a particle born in it by the part after its birth, the path being
        linear over a step) plus any jump since the last carry (older particles only).
        ``compile_only``: launch once over no slot (a warm-up: also for a local emitter added
        later)."""
        if compile_only:
            _local.carry(self.state, 0, 0, [0.0] * 3, [0.0] * 3, 1.0)
            return
        for e in self.local:
            p0, p1 = self.position_at(e, t0), self.position_at(e, t1)
            jump, self._carried[e] = p0 - self._carried[e], p1
            if np.any(p1 != p0) or np.any(jump != 0):
                _local.carry(self.state, self.layout.starts[e], self.layout.sizes[e],
                             (p1 - p0).tolist(), jump.tolist(), t1 - t0)

    @property
    def uses_events(self) -> bool:
        return bool(self.links)

    def position_at(self, e: int, t: float) -> np.ndarray:
        return self.inputs[e].position_at(t)

    def plan(self, t0: float, h: float):
        """Schedule everything due in [t0, t0 + h) (the clocks move on): the spawn launch's plan,
        or None when nothing is due."""
        t1 = t0 + h
        rows, vals, adv, first = [], [], np.zeros((self.count, 4), np.int32), 0
        for e, clock in enumerate(self.clocks):
            plan = clock.schedule(t0, t1, self.inputs[e])
            if not plan:
                continue
            pa, pb = self.position_at(e, t0), self.position_at(e, t1)
            ev = (pb - pa) / h if h > 0 else np.zeros(3)
            start, size = self.layout.starts[e], self.layout.sizes[e]
            a = adv[e]
            a[_k.A_SIZE] = size
            for k, ts0, tspan, at in plan:
                # more than the whole ring in one step (one burst, or the bursts and stream together):
                # the excess never fits (and two births of one launch never aim at one slot)
                skip = max(0, k - (size - a[_k.A_HEAD]))
                k -= skip
                a[_k.A_DROPPED] += skip
                a[_k.A_SERIAL] += skip
                if k:
                    rows.append((e, k, first, a[_k.A_HEAD], a[_k.A_SERIAL], start, size))
                    # a burst placed by code: there, still (the emitter does not move)
                    vals.append((ts0, tspan, *pa, *pb, t0, h, *ev) if at is None else
                                (ts0, tspan, *at, *at, t0, h, 0.0, 0.0, 0.0))
                    first += k
                a[_k.A_HEAD] += k
                a[_k.A_SERIAL] += k
        if not adv[:, _k.A_SIZE].any():
            return None
        nrows = len(rows)
        rows = np.array(rows or [(0,) * 7], np.int32)  # (a dummy row when only drops are due)
        vals = np.array(vals or [(0.0,) * 13], np.float32)
        return rows, vals, nrows, first, adv, np.empty(max(1, first), np.int32)

    def spawn(self, plan) -> None:
        """Write a :meth:`plan`'s particles: one launch for all emitters (none for no plan)."""
        if plan is not None:
            rows, vals, nrows, first, adv, slots = plan
            _k.spawn(self, self.state, rows, vals, nrows, first, adv, slots, runtime.one_thread(first, SERIAL_BIRTHS))

    def emit(self, t0: float, h: float) -> None:
        """Write everything due in [t0, t0 + h) before the step [t0, t0 + h) is taken."""
        self.spawn(self.plan(t0, h))

    def emit_children(self) -> None:
        """Run every sub-emitter link on the events of the step just taken (the next step clears
        them)."""
        L = self.layout
        for p, c, bit, count, min_speed in self.links:
            size = L.sizes[p]
            chunks = max(1, min(CHUNKS, size // CHUNK_MIN))
            _k.spawn_children(self, self.state, self.link_counts, self.link_parent, self.link_slot, L.starts[p],
                              size, chunks, bit, min_speed, c, L.starts[c], L.sizes[c], count,
                              chunks == 1 and runtime.one_thread(min(size * count, L.sizes[c]), SERIAL_CHILDREN))

    def dropped_counts(self) -> np.ndarray:
        return self.dropped.to_numpy()[: len(self.configs)]

    def emitted_counts(self) -> np.ndarray:
        return self.emitter_emitted.to_numpy()[: len(self.configs)]

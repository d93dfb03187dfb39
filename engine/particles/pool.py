"""Particle pools: fixed-capacity struct-of-arrays fields, one ring segment per emitter.

Model (fixed) and State (time-varying) are kept apart: capacities and segment bounds are decided
once, from what the emitters can fill (rate × longest lifetime + the bursts that can be alive at
once), and the fields are allocated once.

Why rings: emitter e owns slots [start_e, start_e + size_e) and writes new particles at its ring
head. A segment of at least rate × max lifetime slots guarantees that a slot is dead when the head
comes back to it; when it is not (a user-set capacity, a burst of long-lived particles), the
new particle takes the next free slot of the segment, from where the last such search ended
(next fit: :func:`engine.particles.spawn.spawn`), and
only when the segment is full is it dropped and counted — never silently overwritten. Allocation is deterministic (no atomics decide
slots) and needs no Python per-particle loop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List

import taichi as ti

from ..launch import data_oriented
from .capacity import emitter_capacity, pool_sizes  # noqa: F401  (re-exported)


@dataclass
class PoolLayout:
    """Model: where each emitter's ring lives. ``starts[e]``, ``sizes[e]``, ``capacity`` total;
    ``spare`` slots after the rings, for emitters added later without reallocating (the
    capacity, a compile-time constant of the kernels, stays)."""

    starts: List[int]
    sizes: List[int]
    spare: int = 0

    @property
    def capacity(self) -> int:
        return sum(self.sizes) + self.spare

    @classmethod
    def for_emitters(cls, emitters, frame_dt: float, spare: int = 0) -> "PoolLayout":
        sizes = pool_sizes(emitters, frame_dt)
        starts, acc = [], 0
        for s in sizes:
            starts.append(acc)
            acc += s
        return cls(starts, sizes, int(spare))

    def take(self, size: int) -> None:
        """A ring of ``size`` slots for a new emitter, from the spare slots."""
        if size > self.spare:
            raise ValueError(f"{size} slots wanted, {self.spare} spare")
        self.starts.append(sum(self.sizes))
        self.sizes.append(int(size))
        self.spare -= int(size)

    def drop_after(self, n: int) -> None:
        """Give the rings of emitters n, n+1, ... back to the spare slots."""
        self.spare += sum(self.sizes[n:])
        del self.starts[n:], self.sizes[n:]


LANES = 4  # slots a block (see ParticleState): the step's vectors, 4 f32 wide (SSE)
# Pools of at least this many slots are kept in blocks and stepped LANES slots side by side: the
# bench's located step at 4M ~1.9x faster, but its two step kernels took 0.97 -> 2.6 s each to
# compile cold (sparks.toml; Taichi's whole-kernel CSE grows with the square of a task, and the
# lanes share one with the slot-at-a-time step their slow slots take). A pool of the shipped
# effects' size (17-30k slots) would save ~0.15 ms a frame for that: smaller pools keep one slot
# per element of each field and their step, compile times and bytes.
BLOCKED_FROM = 65536


def lanes_of(capacity: int) -> int:
    """The length of a blocked pool's per-slot fields: ``capacity`` (at least 1) rounded up to
    whole blocks of LANES slots. The slots past ``capacity`` are never alive; kernels loop over
    the capacity, the step over whole blocks (its last block's extra lanes change nothing)."""
    return -(-max(1, capacity) // LANES) * LANES


# the per-slot state every pool has (optional ones are listed in ParticleState's docstring)
PARTICLE_FIELDS = ("particle_pos", "particle_vel", "particle_age", "particle_life", "particle_alive",
                   "particle_emitter", "particle_rand")


@data_oriented
class ParticleState:
    """State of every slot, shape (capacity,) — (lanes_of(capacity),) for a pool kept in blocks
    (``blocked``: at least BLOCKED_FROM slots; the slots past the capacity unused):

    ``particle_pos`` (vec3 f32, m), ``particle_vel`` (vec3 f32, m/s), ``particle_age`` and
    ``particle_life`` (f32, s), ``particle_alive`` (i32 0/1), ``particle_emitter`` (i32),
    ``particle_rand`` (f32 in [0, 1): per-particle variation for size and colour).
    With adaptive stepping, ``cand_pos``/``cand_vel`` hold the attempted step; with sub-emitters,
    ``particle_event``, ``particle_impact``, ``particle_impact_pos`` and ``particle_impact_lag``
    record deaths and collisions (the last two: where and how long before the step's end it hit);
    with ``interpolate``, ``particle_prev_pos`` (vec3 f32, m) holds where each particle was before
    the last game step (NaN for a slot that was not alive then), what ``render(alpha=)`` draws from
    (each allocated only then).
    """

    def __init__(self, capacity: int, adaptive: bool, events: bool = False, interpolate: bool = False):
        self.capacity = capacity
        self.blocked = capacity >= BLOCKED_FROM
        n = lanes_of(capacity) if self.blocked else max(1, capacity)
        vec3 = lambda: ti.Vector.field(3, ti.f32, shape=n)  # noqa: E731
        scalar = lambda dtype: ti.field(dtype, shape=n)  # noqa: E731
        if self.blocked:
            # What the step reads and writes, in blocks of LANES slots: each component its own
            # array of blocks (x of slots 4b..4b+3 together, y of them in the y array, ...), so
            # the step over a block's slots side by side loads and stores whole 4-wide vectors
            # (engine.particles.integrate._step_lanes; a slot a field apart, the compiler cannot
            # tell that slots 4b and 4b + 1 are neighbours in memory). Not one block holding every
            # component (x4, y4, z4, ... alive4: 144 bytes): there LLVM's SLP vectorizer packed a
            # block's neighbouring x and y values into 8-wide vectors for the bound test and
            # moved single elements between them and the 4-wide z ones (an earlier reading of the
            # compiled step; split, there is no x next to a y to pack; the assembly was not read
            # again). The same bytes (the bench's 1M pool, 200 steps with and without the plane,
            # every 7th slot dead: every field equal) and the same cold compile (6.7 s); the
            # bench's fused step kernel (`particles bench --only step`, alternating processes,
            # 2026-12-04) 4M 10.9/10.7 -> 8.7/8.7 ms, 1M 2.39/2.31 -> 2.19/2.19, and the 1M
            # frame's step (`--only frame`) 6.5 -> 4.2 ms.
            self.particle_pos, self.particle_vel = ti.Vector.field(3, ti.f32), ti.Vector.field(3, ti.f32)
            self.particle_age, self.particle_life = ti.field(ti.f32), ti.field(ti.f32)
            self.particle_alive = ti.field(ti.i32)
            for f in (self.particle_pos, self.particle_vel):
                for c in range(3):
                    ti.root.dense(ti.i, n // LANES).dense(ti.i, LANES).place(f.get_scalar_field(c))
            for f in (self.particle_age, self.particle_life, self.particle_alive):
                ti.root.dense(ti.i, n // LANES).dense(ti.i, LANES).place(f)
        else:
            self.particle_pos, self.particle_vel = vec3(), vec3()
            self.particle_age, self.particle_life = scalar(ti.f32), scalar(ti.f32)
            self.particle_alive = scalar(ti.i32)
        self.particle_emitter = scalar(ti.i32)
        self.particle_rand = scalar(ti.f32)
        if events:  # sub-emitters: what happened to each particle during the last step
            self.particle_event = scalar(ti.i32)  # bit 1 died, bit 2 hit a collider
            self.particle_impact = scalar(ti.f32)  # |Δv| of its last collision, m/s
            self.particle_impact_pos = vec3()  # where it hit (the located point on the surface), m
            self.particle_impact_lag = scalar(ti.f32)  # how long before the step's end it hit, s
        if adaptive:
            self.cand_pos, self.cand_vel = vec3(), vec3()
        self.interpolate = bool(interpolate)
        if interpolate:
            self.particle_prev_pos = vec3()


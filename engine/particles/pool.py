"""Particle pools: fixed-capacity struct-of-arrays fields, one ring segment per emitter.

Model (fixed) and State (time-varying) are kept apart: capacities and segment bounds are decided
once, from what the emitters can fill (rate × longest lifetime + the bursts that can be alive at
once), and the fields are allocated once.

Why rings: emitter e owns slots [start_e, start_e + size_e) and writes new particles at its ring
head. A segment of at least rate × max lifetime slots guarantees that a slot is dead when the head
comes back to it; when it is not (a user-set capacity, a burst too big), the new particle is
dropped and counted — never silently overwritten. Allocation is deterministic (no atomics decide
slots) and needs no Python per-particle loop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List

import taichi as ti


def emitter_capacity(em, frame_dt: float) -> int:
    """Slots emitter ``em`` (a config Emitter) can fill: rate × max lifetime (over its emission
    window) plus the burst particles that can be alive together, plus one frame of slack."""
    if em.capacity is not None:
        return int(em.capacity)
    life = em.lifetime
    window = math.inf if em.stop is None else max(0.0, em.stop - em.start)
    cont = em.rate * min(life + frame_dt, window + frame_dt) if em.rate > 0 else 0.0
    burst = 0
    for b in em.bursts:
        overlapping = 1 if b.cycles == 1 else min(b.cycles, math.ceil(life / b.interval) + 1)
        burst += b.count * overlapping
    return int(math.ceil(cont)) + burst + 8


@dataclass
class PoolLayout:
    """Model: where each emitter's ring lives. ``starts[e]``, ``sizes[e]``, ``capacity`` total."""

    starts: List[int]
    sizes: List[int]

    @property
    def capacity(self) -> int:
        return sum(self.sizes)

    @classmethod
    def for_emitters(cls, emitters, frame_dt: float) -> "PoolLayout":
        sizes = [emitter_capacity(em, frame_dt) for em in emitters]
        names = {em.name: k for k, em in enumerate(emitters) if em.name}
        for em in emitters:  # children: parents' events per second × count × child lifetime
            births = em.rate
            burst_total = sum(b.count * b.cycles for b in em.bursts)
            for sub in em.sub_emitters:
                c = names[sub.emitter]
                if emitters[c].capacity is not None:
                    continue
                per_event = sub.count * (2 if sub.event == "collision" else 1)
                life = emitters[c].lifetime + frame_dt
                sizes[c] += int(math.ceil((births * life + burst_total) * per_event))
        starts, acc = [], 0
        for s in sizes:
            starts.append(acc)
            acc += s
        return cls(starts, sizes)


class ParticleState:
    """State of every slot, shape (capacity,):

    ``particle_pos`` (vec3 f32, m), ``particle_vel`` (vec3 f32, m/s), ``particle_age`` and
    ``particle_life`` (f32, s), ``particle_alive`` (i32 0/1), ``particle_emitter`` (i32),
    ``particle_rand`` (f32 in [0, 1): per-particle variation for size and colour).
    With adaptive stepping, ``cand_pos``/``cand_vel`` hold the attempted step; with sub-emitters,
    ``particle_event`` and ``particle_impact`` record deaths and collisions (each allocated only then).
    """

    def __init__(self, capacity: int, adaptive: bool, events: bool = False):
        n = max(1, capacity)
        self.capacity = capacity
        self.particle_pos = ti.Vector.field(3, ti.f32, shape=n)
        self.particle_vel = ti.Vector.field(3, ti.f32, shape=n)
        self.particle_age = ti.field(ti.f32, shape=n)
        self.particle_life = ti.field(ti.f32, shape=n)
        self.particle_alive = ti.field(ti.i32, shape=n)
        self.particle_emitter = ti.field(ti.i32, shape=n)
        self.particle_rand = ti.field(ti.f32, shape=n)
        if events:  # sub-emitters: what happened to each particle during the last step
            self.particle_event = ti.field(ti.i32, shape=n)  # bit 1 died, bit 2 hit a collider
            self.particle_impact = ti.field(ti.f32, shape=n)  # |Δv| of its last collision, m/s
        if adaptive:
            self.cand_pos = ti.Vector.field(3, ti.f32, shape=n)
            self.cand_vel = ti.Vector.field(3, ti.f32, shape=n)

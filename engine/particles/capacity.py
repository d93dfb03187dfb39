"""How many pool slots an emitter needs (pure Python: the config check uses it without Taichi)."""
from __future__ import annotations

import math

MAX_POOL = 50_000_000  # slots in one scene's pool (about 2.2 GB of particle state)
CODE_DRIVEN_SLOTS = 1024  # an emitter with emitting = false bursts from code: room for that


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
    slots = int(math.ceil(cont)) + burst + 8
    if not getattr(em, "emitting", True):
        slots = max(slots, CODE_DRIVEN_SLOTS)
    return slots


def pool_sizes(emitters, frame_dt: float) -> list:
    """Ring size of every emitter: its own capacity, plus for sub-emitter children what their
    parents can trigger (parent births per second × count × child lifetime, plus parent bursts;
    collisions counted twice per parent)."""
    sizes = [emitter_capacity(em, frame_dt) for em in emitters]
    names = {em.name: k for k, em in enumerate(emitters) if em.name}
    for em in emitters:
        burst_total = sum(b.count * b.cycles for b in em.bursts)
        for sub in em.sub_emitters:
            c = names.get(sub.emitter)
            if c is None or emitters[c].capacity is not None:
                continue
            per_event = sub.count * (2 if sub.event == "collision" else 1)
            life = emitters[c].lifetime + frame_dt
            sizes[c] += int(math.ceil((em.rate * life + burst_total) * per_event))
    return sizes

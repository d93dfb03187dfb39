"""A particle budget shared by every scene of the process (``engine.api.set_particle_budget``).

The budget counts pool slots: a scene allocates its particles up front (rate × lifetime + bursts
per emitter, engine.particles.capacity), so slots bound both the particles alive at once and the
memory and per-step work they cost. Policy when a new scene would pass the budget: its emitters'
pools are scaled down by one common factor so the scene fits what is left (each keeps at least
one slot); a particle that then finds no free slot is not born and is counted in ``dropped()``
— live particles are never overwritten. A scene that cannot get one slot per emitter is refused
(``ValueError`` naming the budget). Scenes already built keep their pools; a discarded scene gives
its slots back. The budget applies to scenes built through the game API.
"""
from __future__ import annotations

import math

from .checks import integer
from .particles.capacity import MAX_POOL, pool_sizes

_limit = [None]
_used = {}  # token -> slots


def set_particle_budget(n) -> None:
    """At most ``n`` pool slots over all scenes built from now on (None: no budget)."""
    _limit[0] = None if n is None else integer("set_particle_budget: n", n, 0, MAX_POOL * 64)


def particle_budget() -> tuple:
    """(budget or None, slots held by live scenes)."""
    return _limit[0], sum(_used.values())


def fit(data: dict, cfg, load, spare=(0, 0)):
    """``(data, cfg, scale, spare)``: the scene's config as the budget lets it be built, and its
    spare (emitter rows, slots) for emitters added later. ``cfg`` is ``data`` validated;
    ``load(data)`` validates a changed copy. ``scale`` is 1 when it fits; short of room the spare
    slots go first (no spare: add_emitter rebuilds), then the emitters' pools shrink."""
    limit = _limit[0]
    sizes = pool_sizes(cfg.emitters, 1.0 / cfg.fps) if cfg.emitters else []
    need, left = sum(sizes), (None if limit is None else limit - sum(_used.values()))
    if left is None or need + spare[1] <= left:
        return data, cfg, 1.0, tuple(spare)
    if need <= left:
        return data, cfg, 1.0, (spare[0], 0)
    if left < len(sizes):
        raise ValueError(f"set_particle_budget: {limit:,} slots is not enough: scenes hold {limit - left:,}, "
                         f"this one needs {need:,} and at least {len(sizes)} (one per emitter)")
    scale = left / need
    emitters = [dict(e, capacity=max(1, math.floor(n * scale))) for e, n in zip(data["emitters"], sizes)]
    data = dict(data, emitters=emitters)
    return data, load(data), scale, (spare[0], 0)


def hold(token, slots: int) -> None:
    _used[token] = int(slots)


def release(token) -> None:
    _used.pop(token, None)

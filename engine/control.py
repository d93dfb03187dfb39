"""Control: this frame's inputs, apart from the Model (fixed) and the State (integrated).

warp.sim's split (``Model``, ``State``, ``Control``): what a game or a config script sets between
frames — emitter positions, rates, emitting flags and bursts, collider positions (their velocities
are inferred from the motion), pins of soft bodies, gravity and wind — lives here and nowhere
else. The game API (:mod:`engine.api`) writes only this object; the systems read it at every step:
the particle and spring kernels read ``gravity`` and ``wind`` (0-d fields: changing them compiles
nothing), the emitters schedule from the emitter inputs, the colliders take their positions from
the collider inputs, each soft body takes its pin requests.

Positions follow keyframed paths (``(time, (x, y, z))`` lists, linear in between, held at the ends):
a config's ``path``, replaced by a two-keyframe path when code moves the thing, so a motion spans
the step it is given for and what it carries (inherited velocity, a pushing collider) sees its
velocity.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Sequence

import numpy as np
import taichi as ti

from .paths import Path, sample_path


def _vec(p) -> tuple:
    return tuple(float(c) for c in p)


@dataclass
class EmitterInput:
    """One emitter's inputs: ``rate`` (particles/s), ``emitting`` (continuous emission on),
    ``bursts`` ((count, position or None) to emit at the start of the next step: at the emitter,
    or at that position without moving it), ``path`` and its rest ``position``."""

    position: tuple
    rate: float = 0.0
    emitting: bool = True
    path: List[tuple] = field(default_factory=list)
    bursts: List[int] = field(default_factory=list)
    name: str = ""

    def position_at(self, t: float) -> np.ndarray:
        return np.asarray(sample_path(self.path, t, self.position), np.float64)


@dataclass
class ColliderInput:
    """One collider's position (a plane's point or a sphere's centre) over time."""

    position: tuple
    path: List[tuple] = field(default_factory=list)
    name: str = ""

    def position_at(self, t: float) -> np.ndarray:
        return np.asarray(sample_path(self.path, t, self.position), np.float64)

    @classmethod
    def from_spec(cls, spec) -> "ColliderInput":
        """Where a :class:`~engine.colliders.ColliderSpec` starts and how its path moves it."""
        return cls(_vec(spec.point), Path((t, _vec(p)) for t, p in spec.path), spec.name)


@dataclass
class PinRequest:
    """A soft body's pin change, applied at the start of its next step: ``kind`` "pin" (hold
    ``node`` at ``target``, or where it is), "move" (drag it to ``target`` over the step) or
    "release"."""

    kind: str
    node: int
    target: Optional[tuple] = None


class Control:
    """``gravity``, ``wind``: 0-d vector fields (m/s², m/s; ``dtype``, f32 for scenes).
    ``emitters``, ``colliders``: one input each, in config order. ``pins``: per soft body, the
    requests not yet applied."""

    def __init__(self, gravity=(0.0, -9.81, 0.0), wind=(0.0, 0.0, 0.0), emitters=(), colliders=(),
                 bodies: int = 0, dtype=ti.f32):
        self.gravity = ti.Vector.field(3, dtype, shape=())
        self.wind = ti.Vector.field(3, dtype, shape=())
        self.gravity[None] = _vec(gravity)
        self.wind[None] = _vec(wind)
        self.emitters: List[EmitterInput] = list(emitters)
        self.colliders: List[ColliderInput] = list(colliders)
        self.pins: List[List[PinRequest]] = [[] for _ in range(bodies)]
        self.body_names: List[str] = [""] * bodies

    @staticmethod
    def inputs_for(cfg, collider_specs):
        """(emitter inputs, collider inputs) a validated config starts with."""
        ems = [EmitterInput(_vec(e.position), e.rate, e.emitting,
                            Path((k.time, _vec(k.position)) for k in e.path), name=e.name)
               for e in cfg.emitters]
        return ems, [ColliderInput.from_spec(s) for s in collider_specs]

    @classmethod
    def for_scene(cls, cfg, collider_specs) -> "Control":
        """The inputs a validated config starts with."""
        ems, cols = cls.inputs_for(cfg, collider_specs)
        new = cls(cfg.forces.gravity, cfg.forces.wind, ems, cols, len(cfg.bodies))
        new.body_names = [b.name for b in cfg.bodies]
        return new

    def restart(self, cfg, collider_specs) -> None:
        """Back to the inputs ``cfg`` starts with, in place: the same fields and lists (kernels
        and systems built against them stay valid; a scene reused for a level restart)."""
        self.set_gravity(cfg.forces.gravity)
        self.set_wind(cfg.forces.wind)
        ems, cols = self.inputs_for(cfg, collider_specs)
        self.emitters[:], self.colliders[:] = ems, cols
        for pending in self.pins:
            pending.clear()

    def rebuilt(self, cfg, collider_specs) -> "Control":
        """The inputs of the same scene rebuilt with ``cfg`` (emitters, colliders or bodies added
        or removed): named emitters and colliders keep what was set on them, gravity and wind
        keep their values and their fields (kernels compiled against them stay valid)."""
        new = Control.for_scene(cfg, collider_specs)
        new.gravity, new.wind = self.gravity, self.wind
        for kind in ("emitters", "colliders"):
            old = {c.name: c for c in getattr(self, kind) if c.name}
            setattr(new, kind, [old.get(c.name, c) if c.name else c for c in getattr(new, kind)])
        names = self.body_names
        new.pins = [self.pins[names.index(n)] if n and n in names else [] for n in new.body_names]
        return new

    # -- forces -----------------------------------------------------------------------------------
    def set_gravity(self, g: Sequence[float]) -> None:
        self.gravity[None] = _vec(g)

    def set_wind(self, w: Sequence[float]) -> None:
        self.wind[None] = _vec(w)

    # -- emitters ---------------------------------------------------------------------------------
    def move_emitter(self, e: int, t_now: float, t_next: float, position) -> None:
        """Emitter e moves linearly to ``position`` by ``t_next``; particles inherit the inferred
        velocity (``inherit_velocity``) and are spread along the motion."""
        em = self.emitters[e]
        em.path = [(t_now, _vec(em.position_at(t_now))), (max(t_next, t_now + 1e-9), _vec(position))]

    def place_emitter(self, e: int, t_now: float, position) -> None:
        """Emitter e jumps to ``position`` (no motion: nothing is inherited)."""
        self.emitters[e].path = [(t_now, _vec(position))]

    def set_rate(self, e: int, rate: float) -> None:
        self.emitters[e].rate = float(rate)

    def set_emitting(self, e: int, on: bool) -> None:
        self.emitters[e].emitting = bool(on)

    def burst(self, e: int, count: int, position=None) -> None:
        """``count`` particles from emitter e at the start of the next step, at ``position`` if
        given (the emitter stays where it is)."""
        self.emitters[e].bursts.append((int(count), None if position is None else _vec(position)))

    # -- colliders --------------------------------------------------------------------------------
    def move_collider(self, k: int, t_now: float, t_next: float, position) -> None:
        """Collider k moves linearly to ``position`` by ``t_next`` (its velocity is inferred, so it
        pushes particles and soft bodies)."""
        c = self.colliders[k]
        c.path = [(t_now, _vec(c.position_at(t_now))), (max(t_next, t_now + 1e-9), _vec(position))]

    @property
    def colliders_move(self) -> bool:
        """Whether any collider follows a path (set by the config or by code)."""
        return any(c.path for c in self.colliders)

    def collider_positions(self, t: float) -> np.ndarray:
        """(K, 3) float64 positions of every collider at time t."""
        return np.array([c.position_at(t) for c in self.colliders], np.float64).reshape(-1, 3)

    # -- soft bodies ------------------------------------------------------------------------------
    def pin(self, body: int, node: int, target=None) -> None:
        self.pins[body].append(PinRequest("pin", int(node), None if target is None else _vec(target)))

    def move_pin(self, body: int, node: int, target) -> None:
        self.pins[body].append(PinRequest("move", int(node), _vec(target)))

    def release(self, body: int, node: int) -> None:
        self.pins[body].append(PinRequest("release", int(node)))

    def take_pins(self, body: int) -> List[PinRequest]:
        """The pending requests of a body, in order (and forget them)."""
        out, self.pins[body] = self.pins[body], []
        return out

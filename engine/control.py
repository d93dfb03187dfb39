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

from .geometry.shapes import quat_mul, quat_normalize, quat_normalize_t, quat_rotvec, spun_t
from .paths import Path, sample_path, sample_path_t


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
    """One shape's pose over time: its position (a plane's point or a shape's centre) on a
    keyframed path, and its orientation [w, x, y, z], ``orientation`` at ``orientation_time``
    spun at the constant world ``angular_velocity`` (rad/s) before and after it. ``posed``: the
    orientation or spin was set from code (the table then follows it at every step)."""

    position: tuple
    path: List[tuple] = field(default_factory=list)
    name: str = ""
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)
    orientation_time: float = 0.0
    posed: bool = False

    def position_at(self, t: float) -> np.ndarray:
        return np.asarray(sample_path(self.path, t, self.position), np.float64)

    def orientation_at(self, t: float) -> np.ndarray:
        return np.array(self.orientation_t(t), np.float64)

    def position_t(self, t: float) -> tuple:
        """:meth:`position_at` as a 3-tuple of floats (several calls a step per shape)."""
        return sample_path_t(self.path, t, self.position)

    def orientation_t(self, t: float) -> tuple:
        """:meth:`orientation_at` as a 4-tuple of floats (several calls a step per turning shape)."""
        q = quat_normalize_t(*map(float, self.orientation))
        if not any(self.angular_velocity):
            return q
        return spun_t(q, tuple(map(float, self.angular_velocity)), t - self.orientation_time)

    @property
    def turns(self) -> bool:
        return self.posed or any(self.angular_velocity)

    @classmethod
    def from_spec(cls, spec) -> "ColliderInput":
        """Where a :class:`~engine.colliders.ColliderSpec` starts and how its path moves and its
        angular velocity turns it."""
        return cls(_vec(spec.point), Path((t, _vec(p)) for t, p in spec.path), spec.name,
                   tuple(float(c) for c in spec.orientation), _vec(spec.angular_velocity))


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

    def set_collider_pose(self, k: int, t0: float, t1: float, position, orientation=None, velocity=None,
                          angular_velocity=None) -> None:
        """Shape k's pose over the step [t0, t1] (a rigid body publishing its shape each coupling
        step, or a game steering a collider): at t1 it is at ``position`` (m) with ``orientation``
        [w, x, y, z] (None: as it turns now). ``velocity`` (m/s): its linear velocity over the
        step, so it was at position − velocity·(t1 − t0) at t0 (None: from where it is at t0, as
        :meth:`move_collider`). ``angular_velocity`` (rad/s, world; None: the rotation from its
        orientation at t0 to ``orientation`` over the step, or its spin so far when no
        orientation is given); it keeps turning at that rate after t1 until set again. Spinning
        needs a shape built to rotate (the table says so when the step places it)."""
        c = self.colliders[k]
        h = max(t1 - t0, 1e-9)
        p1 = np.asarray(position, np.float64)
        p0 = c.position_at(t0) if velocity is None else p1 - np.asarray(velocity, np.float64) * h
        c.path = [(t0, _vec(p0)), (t0 + h, _vec(p1))]
        q0 = c.orientation_at(t0)
        if orientation is None:
            w = c.angular_velocity if angular_velocity is None else _vec(angular_velocity)
            c.orientation, c.orientation_time = tuple(q0.tolist()), float(t0)
        else:
            q1 = quat_normalize(orientation)
            w = (_vec(angular_velocity) if angular_velocity is not None
                 else _vec(quat_rotvec(quat_mul(q1, q0 * [1.0, -1.0, -1.0, -1.0])) / h))
            c.orientation, c.orientation_time = tuple(q1.tolist()), float(t0 + h)
        c.angular_velocity, c.posed = _vec(w), True

    @property
    def colliders_move(self) -> bool:
        """Whether any collider follows a path or turns (set by the config or by code)."""
        return any(c.path or c.turns for c in self.colliders)

    @property
    def colliders_turn(self) -> bool:
        """Whether any collider's orientation changes (a spin, or a pose set from code)."""
        return any(c.turns for c in self.colliders)

    def collider_positions(self, t: float) -> np.ndarray:
        """(K, 3) float64 positions of every collider at time t."""
        return np.array([c.position_t(t) for c in self.colliders], np.float64).reshape(-1, 3)

    def collider_orientations(self, t: float) -> np.ndarray:
        """(K, 4) float64 orientations [w, x, y, z] of every collider at time t."""
        return np.array([c.orientation_t(t) for c in self.colliders], np.float64).reshape(-1, 4)

    def collider_omegas(self) -> np.ndarray:
        """(K, 3) float64 angular velocities (rad/s, world) of every collider now."""
        return np.array([c.angular_velocity for c in self.colliders], np.float64).reshape(-1, 3)

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

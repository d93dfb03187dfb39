"""The game API's rigid-body calls (a mixin of :class:`engine.api.ParticleScene`): read a body's
state, push it, place it, set its velocity, add and remove bodies. Every argument is checked first
(:mod:`engine.checks`: one line naming the argument and the value; a refused call changes
nothing), then the scene's rigid system is asked through its public methods."""
from __future__ import annotations

import math

import numpy as np

from . import checks
from .checks import COORD, vector

MAX_IMPULSE = 1e9  # N·s


class RigidAPI:
    """Rigid bodies from code. Needs ``self._live(where)`` and ``self._add``/``self._remove``."""

    def _rigid(self, where: str, name):
        s = self._live(where)
        system = s.rigid
        names = system.model.names if system is not None else []
        checks.name(f"{where}: name", name, names, "rigid body")
        return system, system.model.index(name)

    def rigid_state(self, name: str) -> dict:
        """``position``, ``orientation`` (w, x, y, z), ``velocity`` and ``angular_velocity``
        (world frame) of rigid body ``name``, as float64 NumPy arrays (copies)."""
        system, i = self._rigid("rigid_state", name)
        return system.body_state(i)

    def apply_impulse(self, name: str, impulse, point=None) -> None:
        """Add ``impulse`` (N·s, world) to rigid body ``name`` at the start of the next step, at
        its centre of mass or at the world ``point`` (which also spins it). Fixed and kinematic
        bodies take none."""
        system, i = self._rigid("apply_impulse", name)
        J = vector("apply_impulse: impulse", impulse, bound=MAX_IMPULSE)
        p = None if point is None else vector("apply_impulse: point", point)
        system.pending.append((i, J, p))

    def set_rigid_pose(self, name: str, position=None, orientation=None) -> None:
        """Place rigid body ``name`` at ``position`` (m) and/or ``orientation`` (a unit quaternion
        [w, x, y, z]; its length must be 1 within 1e-3), now."""
        system, i = self._rigid("set_rigid_pose", name)
        p = None if position is None else vector("set_rigid_pose: position", position)
        q = None
        if orientation is not None:
            q = vector("set_rigid_pose: orientation", orientation, n=4, bound=2.0)
            if abs(math.sqrt(sum(c * c for c in q)) - 1.0) > 1e-3:
                raise ValueError(f"set_rigid_pose: orientation: {checks.show(orientation)} is not allowed: "
                                 f"must be a unit quaternion [w, x, y, z] (length 1 within 1e-3)")
        system.set_pose(i, p, None if q is None else np.asarray(q))

    def set_rigid_velocity(self, name: str, velocity=None, angular_velocity=None) -> None:
        """Set rigid body ``name``'s ``velocity`` (m/s) and/or ``angular_velocity`` (rad/s, world
        frame), now. A fixed body refuses any."""
        system, i = self._rigid("set_rigid_velocity", name)
        v = None if velocity is None else vector("set_rigid_velocity: velocity", velocity)
        w = None if angular_velocity is None else vector("set_rigid_velocity: angular_velocity",
                                                         angular_velocity, bound=COORD)
        if not system.model.dynamic[i] and (v is not None or w is not None):
            raise ValueError(f"set_rigid_velocity: name: {name!r} is fixed or follows a path: it takes "
                             f"no velocity")
        system.set_velocity(i, v, w)

    def add_rigid_body(self, body: dict) -> None:
        """Add a ``[[rigid_bodies]]`` entry (a dict of config keys, checked as a config is);
        the scene is rebuilt between frames, other bodies keep their state by name."""
        self._add("add_rigid_body", "rigid_bodies", body)

    def remove_rigid_body(self, name: str) -> None:
        self._rigid("remove_rigid_body", name)
        self._remove("remove_rigid_body", "rigid_bodies", name)

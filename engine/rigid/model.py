"""The rigid bodies of a scene: Model (fixed: shapes, masses, inverse inertia in the body frame,
materials) and State (x, q, v, ω in float64 on the CPU: Müller et al. 2020 found small substeps
need double precision). warp.sim's prefixes: ``body_*`` per body."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import quat, shapes

DEFAULT_DENSITY = 1000.0  # kg/m³ when a body gives neither density nor mass


class RigidModel:
    """Arrays over the bodies, in config order: ``body_shape`` (shapes.SPHERE/BOX/CAPSULE),
    ``body_radius``, ``body_half`` (N, 3) box half extents, ``body_half_length`` (capsules),
    ``body_mass``, ``body_inv_mass`` (0 for fixed and kinematic bodies), ``body_inertia`` and
    ``body_inv_inertia`` (N, 3) principal moments in the body frame, ``body_restitution``,
    ``body_friction``, ``body_fixed``, ``body_kinematic``, ``body_bound`` (bounding radius),
    ``body_color``; ``names``; ``paths`` (keyframes of kinematic bodies)."""

    def __init__(self, bodies):
        n = len(bodies)
        self.count = n
        self.names = [b.name for b in bodies]
        self.body_shape = np.array([shapes.CODES[b.shape] for b in bodies], np.int32)
        self.body_radius = np.array([b.radius or 0.0 for b in bodies], np.float64)
        self.body_half = np.array([b.half_extents or (0.0, 0.0, 0.0) for b in bodies], np.float64).reshape(n, 3)
        self.body_half_length = np.array([b.half_length or 0.0 for b in bodies], np.float64)
        self.body_mass = np.zeros(n)
        self.body_inertia = np.zeros((n, 3))
        for i, b in enumerate(bodies):
            k = self.body_shape[i]
            args = (self.body_radius[i], self.body_half[i], self.body_half_length[i])
            m = b.mass if b.mass is not None else (b.density or DEFAULT_DENSITY) * shapes.volume(k, *args)
            self.body_mass[i] = m
            self.body_inertia[i] = shapes.inertia(k, m, *args)
        self.body_fixed = np.array([b.fixed for b in bodies], bool)
        self.body_kinematic = np.array([bool(b.path) for b in bodies], bool)
        moving = ~(self.body_fixed | self.body_kinematic)
        self.body_inv_mass = np.where(moving, 1.0 / np.maximum(self.body_mass, 1e-300), 0.0)
        self.body_inv_inertia = np.where(moving[:, None], 1.0 / np.maximum(self.body_inertia, 1e-300), 0.0)
        self.body_restitution = np.array([b.restitution for b in bodies], np.float64)
        self.body_friction = np.array([b.friction for b in bodies], np.float64)
        self.body_bound = np.array([shapes.bounding_radius(self.body_shape[i], self.body_radius[i],
                                                           self.body_half[i], self.body_half_length[i])
                                    for i in range(n)], np.float64)
        self.body_color = np.array([b.color for b in bodies], np.float64).reshape(n, 3)
        self.paths = [[(k.time, k.position) for k in b.path] for b in bodies]
        self.dynamic = moving

    def index(self, name: str) -> int:
        return self.names.index(name)

    def inv_inertia_world(self, q, i, v):
        """I⁻¹ v in the world frame for bodies ``i`` at orientations ``q``: R I_b⁻¹ Rᵀ v."""
        return quat.rotate(q, self.body_inv_inertia[i] * quat.rotate_inv(q, v))


@dataclass
class RigidState:
    """x (N, 3) centre of mass, q (N, 4) orientation [w, x, y, z], v (N, 3), w (N, 3) angular
    velocity in the world frame. float64."""

    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray

    @classmethod
    def from_config(cls, bodies) -> "RigidState":
        n = len(bodies)
        x = np.array([b.position for b in bodies], np.float64).reshape(n, 3)
        q = quat.normalize(np.array([b.orientation for b in bodies], np.float64).reshape(n, 4)) if n else np.zeros((0, 4))
        v = np.array([b.velocity for b in bodies], np.float64).reshape(n, 3)
        w = np.array([b.angular_velocity for b in bodies], np.float64).reshape(n, 3)
        return cls(x, q, v, w)

    def copy(self) -> "RigidState":
        return RigidState(self.x.copy(), self.q.copy(), self.v.copy(), self.w.copy())

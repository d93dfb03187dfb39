"""Pinhole camera: position, look-at point, vertical field of view; y is up."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Camera:
    position: tuple = (0.0, 2.0, 8.0)
    look_at: tuple = (0.0, 1.0, 0.0)
    fov: float = 45.0  # vertical, degrees

    def basis(self):
        """(position, forward, right, up) as float32 arrays; right-handed, y up."""
        p = np.asarray(self.position, np.float64)
        f = np.asarray(self.look_at, np.float64) - p
        f /= max(np.linalg.norm(f), 1e-12)
        world_up = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.999 else np.array([0.0, 0.0, -1.0])
        r = np.cross(f, world_up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        return tuple(a.astype(np.float32) for a in (p, f, r, u))

    @property
    def tan_half(self) -> float:
        return math.tan(math.radians(self.fov) / 2.0)

    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """World points (N, 3) → pixel coordinates (N, 2) and view depth (N,), as (N, 3)."""
        p, f, r, u = self.basis()
        d = np.asarray(points, np.float64) - p
        z = d @ f
        th = self.tan_half
        aspect = width / height
        xn = (d @ r) / (z * th * aspect)
        yn = (d @ u) / (z * th)
        return np.stack([(xn + 1) * 0.5 * width, (1 - yn) * 0.5 * height, z], axis=1)

"""Keyframed paths: piecewise-linear position over time, for moving emitters and colliders."""
from __future__ import annotations

from typing import Sequence

import numpy as np


def sample_path(path: Sequence, t: float, default: Sequence[float]) -> np.ndarray:
    """Position at time t from keyframes [(time, (x, y, z)), ...] sorted by time; clamped at the
    ends. An empty path gives ``default``."""
    if not path:
        return np.asarray(default, np.float64)
    times = np.array([k[0] for k in path], np.float64)
    pts = np.array([k[1] for k in path], np.float64)
    if t <= times[0]:
        return pts[0]
    if t >= times[-1]:
        return pts[-1]
    j = int(np.searchsorted(times, t, side="right")) - 1
    a = (t - times[j]) / (times[j + 1] - times[j])
    return (1 - a) * pts[j] + a * pts[j + 1]

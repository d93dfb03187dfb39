"""Keyframed paths: piecewise-linear position over time, for moving emitters and colliders.

A config's path is turned into a :class:`Path` once (a list of keyframes that also keeps them as
NumPy arrays), so sampling it each step is a binary search (``np.searchsorted``), not a re-read
of every keyframe: a path of a million keyframes costs microseconds a step.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np


class Path(list):
    """Keyframes [(time, (x, y, z)), ...] sorted by time (a list, as the config gives them), with
    their times and points kept as arrays for :func:`sample_path`."""

    def __init__(self, keys=()):
        super().__init__(keys)
        self.times = np.array([k[0] for k in self], np.float64)
        self.points = np.array([k[1] for k in self], np.float64).reshape(len(self), 3)


def sample_path(path: Sequence, t: float, default: Sequence[float]) -> np.ndarray:
    """Position at time t from keyframes [(time, (x, y, z)), ...] sorted by time; clamped at the
    ends. An empty path gives ``default``. A :class:`Path` is searched as it is; any other
    sequence (a two-keyframe motion from code) is read into arrays first."""
    if not len(path):
        return np.asarray(default, np.float64)
    if not isinstance(path, Path):
        path = Path(path)
    times, pts = path.times, path.points
    if t <= times[0]:
        return pts[0].copy()
    if t >= times[-1]:
        return pts[-1].copy()
    j = int(np.searchsorted(times, t, side="right")) - 1
    a = (t - times[j]) / (times[j + 1] - times[j])
    return (1 - a) * pts[j] + a * pts[j + 1]

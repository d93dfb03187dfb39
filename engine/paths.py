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


def sample_path_t(path: Sequence, t: float, default: Sequence[float]) -> tuple:
    """:func:`sample_path` as a 3-tuple of floats. A two-keyframe motion that is not a
    :class:`Path` (a pose set from code, a rigid body's shape over a step: several a step each) is
    interpolated on floats, the same arithmetic per component without building arrays."""
    if not len(path):
        return tuple(float(c) for c in default)
    if len(path) == 2 and not isinstance(path, Path):
        (t0, p0), (t1, p1) = path
        t0, t1 = float(t0), float(t1)
        if t <= t0:
            return tuple(float(c) for c in p0)
        if t >= t1:
            return tuple(float(c) for c in p1)
        a = (t - t0) / (t1 - t0)
        return tuple((1 - a) * float(u) + a * float(v) for u, v in zip(p0, p1))
    return tuple(sample_path(path, t, default).tolist())


def sample_path(path: Sequence, t: float, default: Sequence[float]) -> np.ndarray:
    """Position at time t from keyframes [(time, (x, y, z)), ...] sorted by time; clamped at the
    ends. An empty path gives ``default``. A :class:`Path` is searched as it is; any other
    sequence is read into arrays first (a two-keyframe one is :func:`sample_path_t`'s)."""
    if not len(path):
        return np.asarray(default, np.float64)
    if not isinstance(path, Path):
        if len(path) == 2:
            return np.array(sample_path_t(path, t, default), np.float64)
        path = Path(path)
    times, pts = path.times, path.points
    if t <= times[0]:
        return pts[0].copy()
    if t >= times[-1]:
        return pts[-1].copy()
    j = int(np.searchsorted(times, t, side="right")) - 1
    a = (t - times[j]) / (times[j + 1] - times[j])
    return (1 - a) * pts[j] + a * pts[j + 1]

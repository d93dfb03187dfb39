"""Unit quaternions [w, x, y, z] on NumPy arrays of shape (..., 4), float64: products, rotation of
vectors, matrices (the kernels' own copies are in engine.rigid.kernel)."""
from __future__ import annotations

import numpy as np


def cross(a, b):
    """a × b over the last axis (np.cross costs several times more on small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def mul(a, b):
    """Hamilton product a ⊗ b (rotation b, then a)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], -1)


def conj(q):
    q = np.array(q, np.float64)
    q[..., 1:] *= -1.0
    return q


def rotate(q, v):
    """R(q) v for unit q: v + 2w (u × v) + 2 u × (u × v), u = vec(q)."""
    q = np.asarray(q, np.float64)
    u, w = q[..., 1:], q[..., :1]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def rotate_inv(q, v):
    """R(q)ᵀ v."""
    return rotate(conj(q), v)


def matrix(q):
    """(..., 3, 3) rotation matrices."""
    q = np.asarray(q, np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def normalize(q):
    q = np.asarray(q, np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def from_axis_angle(axis, angle):
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    h = 0.5 * np.asarray(angle, np.float64)[..., None]
    return np.concatenate([np.cos(h), np.sin(h) * axis], -1)

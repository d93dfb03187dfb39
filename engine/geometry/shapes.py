"""Shapes: plane, sphere, box and capsule — signed distance, closest point, outward normal, mass
properties — and the rotation helpers their poses need.

A shape sits at a pose (position p, orientation q) and is described in its own frame:
* plane: the points with (x − p)·N ≥ 0 are outside; N is the rest normal rotated by q;
* sphere: radius R about p;
* box: half extents h along the body axes (R(q) e_x, e_y, e_z);
* capsule: the points within ``radius`` of the segment p ± ``half_length``·a, a = R(q) e_y.

Signed distance g(x) (negative inside), its gradient N (the outward unit normal at the closest
surface point) and the closest point x − g N. Box: Quilez's exact distance, d = |q_b| − h,
g = |max(d, 0)| + min(max_i d_i, 0) with q_b the point in the box's frame. Capsule:
g = |r − clamp(r·a, −L, L) a| − R with r = x − p.

Quaternions are [w, x, y, z] (Hamilton, unit). A pose moving over a step with constant linear
velocity v and angular velocity ω (world frame) is at p(t) = p₁ − v (t₁ − t) and
q(t) = exp(−ω (t₁ − t)/2) ⊗ q₁; a point fixed to the shape moves at v + ω × (x − p).

Two sides: NumPy in float64 (the reference and the host's pose arithmetic) and ``ti.func`` s over
a dtype-generic Taichi scope (the kernels' narrow phase, :mod:`engine.colliders`).
"""
# (no __future__ annotations: Taichi reads the funcs' ti.template() annotations)

import math

import numpy as np
import taichi as ti

PLANE, SPHERE, BOX, CAPSULE = 0, 1, 2, 3
KINDS = ("plane", "sphere", "box", "capsule")


# -- quaternions and rotations (float64) ------------------------------------------------------------
# The host turns a shape's pose several times a step for every turning shape (a rigid body's shape
# is followed at every particle step: engine.collider_poses), so the arithmetic is done on Python
# floats (``*_t``: tuples), several times cheaper than the same few operations on 4-vectors in
# NumPy, and the NumPy functions below are those, wrapped. Sums run left to right, the order
# NumPy's dot of a 3- or 4-vector takes here (OpenBLAS's scalar loop for short vectors: the same
# sums on 200,000 random vectors, where a pairwise order differs in 20 % of them), so the poses
# kept their bytes when this moved from arrays to floats.
def quat_normalize_t(w, x, y, z) -> tuple:
    """q / |q| of q = (w, x, y, z) as floats; ValueError on a zero quaternion."""
    n = math.sqrt(((w * w + x * x) + y * y) + z * z)
    if not n > 1e-12:
        raise ValueError(f"orientation: a quaternion [w, x, y, z] must not be zero, got {[w, x, y, z]}")
    return (w / n, x / n, y / n, z / n)


def quat_mul_t(a, b) -> tuple:
    """The Hamilton product a ⊗ b of two 4-tuples (rotate by b, then by a)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_from_rotvec_t(wx, wy, wz) -> tuple:
    """exp of the rotation vector (wx, wy, wz) (axis·angle, rad): (cos(θ/2), sin(θ/2) ŵ)."""
    th = math.sqrt((wx * wx + wy * wy) + wz * wz)
    if th < 1e-300:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(th / 2)
    return (math.cos(th / 2), s * wx / th, s * wy / th, s * wz / th)


def spun_t(q, omega, dt: float) -> tuple:
    """:func:`spun` on floats: q (4,) and ω (3,) as sequences of floats, a unit 4-tuple out."""
    wx, wy, wz = omega
    return quat_normalize_t(*quat_mul_t(quat_from_rotvec_t(wx * dt, wy * dt, wz * dt), q))


def quat_matrix_t(q) -> tuple:
    """The rotation matrix of q (normalised first) as 9 floats, row-major."""
    w, x, y, z = quat_normalize_t(*q)
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


def _floats(q, n: int) -> list:
    return np.asarray(q, np.float64).reshape(n).tolist()


def quat_normalize(q) -> np.ndarray:
    """q / |q| as float64 [w, x, y, z]; ValueError on a zero quaternion."""
    return np.array(quat_normalize_t(*_floats(q, 4)), np.float64)


def quat_mul(a, b) -> np.ndarray:
    """The Hamilton product a ⊗ b (rotate by b, then by a)."""
    return np.array(quat_mul_t(_floats(a, 4), _floats(b, 4)), np.float64)


def quat_from_rotvec(w) -> np.ndarray:
    """exp of the rotation vector w (axis·angle, rad): [cos(θ/2), sin(θ/2) ŵ]."""
    return np.array(quat_from_rotvec_t(*_floats(w, 3)), np.float64)


def quat_rotvec(q) -> np.ndarray:
    """log of the unit quaternion q: the rotation vector (rad) of the shorter rotation."""
    q = quat_normalize(q)
    if q[0] < 0:
        q = -q
    s = math.sqrt(float(q[1:] @ q[1:]))
    if s < 1e-300:
        return np.zeros(3)
    return 2.0 * math.atan2(s, q[0]) * q[1:] / s


def quat_to_matrix(q) -> np.ndarray:
    """(3, 3) rotation matrix of the unit quaternion q (columns: the body axes in world)."""
    return np.array(quat_matrix_t(_floats(q, 4)), np.float64).reshape(3, 3)


def spun(q, omega, dt: float) -> np.ndarray:
    """The orientation ``dt`` seconds after q under constant world angular velocity ω (rad/s):
    exp(ω dt/2) ⊗ q (dt may be negative)."""
    return np.array(spun_t(_floats(q, 4), _floats(omega, 3), float(dt)), np.float64)


# -- signed distance (NumPy reference, float64) ---------------------------------------------------
def signed_distance(kind: str, x, position, orientation=(1.0, 0.0, 0.0, 0.0), *, normal=(0.0, 1.0, 0.0),
                    radius: float = 1.0, half_extents=(0.5, 0.5, 0.5), half_length: float = 0.5):
    """(g, N) of point x (3,) against a shape at (position, orientation): the signed distance (m,
    negative inside) and the outward unit normal at the closest surface point."""
    x, p = np.asarray(x, np.float64), np.asarray(position, np.float64)
    R = quat_to_matrix(orientation)
    r = x - p
    if kind == "plane":
        n = R @ (np.asarray(normal, np.float64) / np.linalg.norm(normal))
        return float(r @ n), n
    if kind == "sphere":
        d = np.linalg.norm(r)
        return float(d - radius), (r / d if d > 1e-12 else np.array([0.0, 1.0, 0.0]))
    if kind == "box":
        qb = R.T @ r
        h = np.asarray(half_extents, np.float64)
        d = np.abs(qb) - h
        sgn = np.where(qb < 0, -1.0, 1.0)
        out = np.maximum(d, 0.0)
        if out.any():
            nl = out * sgn / np.linalg.norm(out)
            return float(np.linalg.norm(out)), R @ nl
        i = int(np.argmax(d))
        nl = np.zeros(3)
        nl[i] = sgn[i]
        return float(d[i]), R @ nl
    if kind == "capsule":
        a = R[:, 1]
        s = float(np.clip(r @ a, -half_length, half_length))
        d = r - s * a
        dist = np.linalg.norm(d)
        return float(dist - radius), (d / dist if dist > 1e-12 else np.array([0.0, 1.0, 0.0]))
    raise ValueError(f"kind: unknown shape {kind!r}; allowed: {', '.join(KINDS)}")


def closest_point(kind: str, x, position, orientation=(1.0, 0.0, 0.0, 0.0), **shape) -> np.ndarray:
    """The surface point nearest x: x − g N (:func:`signed_distance`)."""
    g, n = signed_distance(kind, x, position, orientation, **shape)
    return np.asarray(x, np.float64) - g * n


def inertia(kind: str, mass: float, *, radius: float = 1.0, half_extents=(0.5, 0.5, 0.5),
            half_length: float = 0.5) -> np.ndarray:
    """(3, 3) inertia tensor (kg·m²) of a solid shape of uniform density about its centre, in its
    own frame. Sphere 2/5 m R²; box m/3 (h_y² + h_z², …); capsule: a cylinder of length 2L (axis
    y) and two hemispheres, I_y = m_c R²/2 + 2·(2/5) m_h R², I_x = I_z = m_c (R²/4 + L²/3) +
    2 m_h (2/5 R² + L² + 3/4 L R) (each hemisphere's own moment moved to the centre by the
    parallel-axis theorem, its centroid 3R/8 from its flat face). A plane has no finite inertia."""
    m = float(mass)
    if kind == "sphere":
        return np.eye(3) * 0.4 * m * radius * radius
    if kind == "box":
        hx, hy, hz = (float(c) for c in half_extents)
        return np.diag([hy * hy + hz * hz, hx * hx + hz * hz, hx * hx + hy * hy]) * m / 3.0
    if kind == "capsule":
        R, L = float(radius), float(half_length)
        v_c, v_h = math.pi * R * R * 2 * L, 2.0 / 3.0 * math.pi * R ** 3
        m_c = m * v_c / (v_c + 2 * v_h)
        m_h = m * v_h / (v_c + 2 * v_h)
        iy = m_c * R * R / 2 + 2 * 0.4 * m_h * R * R
        ix = m_c * (R * R / 4 + L * L / 3) + 2 * m_h * (0.4 * R * R + L * L + 0.75 * L * R)
        return np.diag([ix, iy, ix])
    raise ValueError(f"inertia: a {kind!r} has no finite inertia (sphere, box or capsule)")


# -- the kernels' side (ti.func, any float dtype) ---------------------------------------------------
@ti.func
def turn(w, s):
    """(k, cos θ, sin θ) of the rotation by the rotation vector w·s (θ = |w|·s, k = w/|w|; k = 0
    when w = 0): what :func:`turned` applies, computed once for several vectors."""
    wn = w.norm()
    th = wn * s
    k = w / ti.max(wn, 1e-30)  # (w = 0: k = 0, θ = 0, no turn; no branch: this is inlined a lot)
    return k, ti.cos(th), ti.sin(th)


@ti.func
def turned(v, k, c, sn):
    """v rotated about the unit axis k by the angle whose cosine and sine are c, sn (Rodrigues:
    v cos θ + (k × v) sin θ + k (k·v)(1 − cos θ))."""
    return v * c + k.cross(v) * sn + k * (k.dot(v) * (1.0 - c))


@ti.func
def rotate(v, w, s):
    """v rotated by the rotation vector w·s: a shape spinning at ω is turned back to lag s
    before the step's end by ``rotate(v, ω, −s)``."""
    k, c, sn = turn(w, s)
    return turned(v, k, c, sn)


@ti.func
def box_local(r, ex, ey, ez, h):
    """(g, N) of the offset r from a box's centre, its body axes ex, ey, ez (unit, world) and
    half extents h: the exact signed distance and the outward normal (world). Outside: toward the
    nearest face, edge or corner; inside: the face whose plane is nearest (ties: the lower axis).
    Written without branches (selects): it is inlined at every contact site of a located step,
    and a branchy form compiled twice as slowly."""
    q0, q1, q2 = r.dot(ex), r.dot(ey), r.dot(ez)
    s0 = ti.select(q0 >= 0.0, 1.0, -1.0)
    s1 = ti.select(q1 >= 0.0, 1.0, -1.0)
    s2 = ti.select(q2 >= 0.0, 1.0, -1.0)
    d0, d1, d2 = ti.abs(q0) - h[0], ti.abs(q1) - h[1], ti.abs(q2) - h[2]
    o0, o1, o2 = ti.max(d0, 0.0), ti.max(d1, 0.0), ti.max(d2, 0.0)
    on = ti.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    a0 = (d0 >= d1) & (d0 >= d2)
    a1 = (~a0) & (d1 >= d2)
    a2 = ~(a0 | a1)
    inside = on <= 0.0
    g = ti.select(inside, ti.max(d0, d1, d2), on)
    inv = 1.0 / ti.max(on, 1e-30)
    n0 = ti.select(inside, ti.select(a0, s0, 0.0), s0 * o0 * inv)
    n1 = ti.select(inside, ti.select(a1, s1, 0.0), s1 * o1 * inv)
    n2 = ti.select(inside, ti.select(a2, s2, 0.0), s2 * o2 * inv)
    return g, n0 * ex + n1 * ey + n2 * ez

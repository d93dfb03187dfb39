"""Rigid shapes: sphere, box, capsule (axis along local y). Volume and inertia about the centre in
closed form (the principal axes are the body axes, so the body-frame inertia is diagonal), bounding
radius, and a triangle mesh in body coordinates for drawing (flat faces for boxes: each face has
its own four vertices, so the renderer's per-vertex normals stay sharp)."""
from __future__ import annotations

import math

import numpy as np

SPHERE, BOX, CAPSULE = 0, 1, 2
CODES = {"sphere": SPHERE, "box": BOX, "capsule": CAPSULE}


def volume(kind: int, radius: float, half, half_length: float) -> float:
    if kind == SPHERE:
        return 4.0 / 3.0 * math.pi * radius ** 3
    if kind == BOX:
        return 8.0 * half[0] * half[1] * half[2]
    return math.pi * radius ** 2 * 2.0 * half_length + 4.0 / 3.0 * math.pi * radius ** 3


def inertia(kind: int, mass: float, radius: float, half, half_length: float) -> np.ndarray:
    """Principal moments (Ixx, Iyy, Izz) about the centre, kg·m²."""
    if kind == SPHERE:
        return np.full(3, 0.4 * mass * radius ** 2)
    if kind == BOX:
        a, b, c = (2.0 * h for h in half)
        return mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    # capsule: a cylinder of length 2l plus two hemispheres (mass split by volume)
    r, l = radius, half_length
    vc, vs = math.pi * r * r * 2 * l, 4.0 / 3.0 * math.pi * r ** 3
    mc, ms = mass * vc / (vc + vs), mass * vs / (vc + vs)
    iy = 0.5 * mc * r * r + 0.4 * ms * r * r
    # hemispheres: about their own centre of mass 2/5 ms r² (both halves), shifted to the caps
    # at ±(l + 3r/8) by the parallel axis theorem from the centroid at 3r/8
    ix = mc * (r * r / 4 + (2 * l) ** 2 / 12) + ms * (0.4 * r * r + l * l + 0.75 * l * r)
    return np.array([ix, iy, ix])


def bounding_radius(kind: int, radius: float, half, half_length: float) -> float:
    if kind == SPHERE:
        return radius
    if kind == BOX:
        return float(np.linalg.norm(half))
    return radius + half_length


def mesh(kind: int, radius: float, half, half_length: float, detail: int = 12):
    """(vertices (V, 3), triangles (T, 3)) in body coordinates."""
    if kind == BOX:
        h = np.asarray(half, np.float64)
        verts, tris = [], []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                u, v = (axis + 1) % 3, (axis + 2) % 3
                base = len(verts)
                for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                    p = np.zeros(3)
                    p[axis], p[u], p[v] = sign * h[axis], du * h[u], dv * h[v]
                    verts.append(p)
                tris += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
        return np.array(verts), np.array(tris, np.int32)
    # sphere or capsule: a UV sphere split at the equator, the halves moved apart by ±half_length
    n_lat, n_lon = detail // 2 * 2, detail * 2
    l = half_length if kind == CAPSULE else 0.0
    verts = []
    for i in range(n_lat + 1):
        th = math.pi * i / n_lat
        y = radius * math.cos(th)
        shift = l if i < n_lat // 2 else -l
        rows = 2 if (kind == CAPSULE and i == n_lat // 2) else 1
        for k in range(rows):
            s = (l if k == 0 else -l) if rows == 2 else shift
            for j in range(n_lon):
                ph = 2 * math.pi * j / n_lon
                verts.append((radius * math.sin(th) * math.cos(ph), y + s, radius * math.sin(th) * math.sin(ph)))
    rows_total = n_lat + 1 + (1 if kind == CAPSULE else 0)
    tris = []
    for i in range(rows_total - 1):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = a + n_lon, b + n_lon
            tris += [(a, c, b), (b, c, d)]
    return np.array(verts, np.float64), np.array(tris, np.int32)

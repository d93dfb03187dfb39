"""Spring-network topologies as plain numpy data: chains, hair, cloth, jelly; merged by offsets.

Builders return a :class:`Topology` (nothing here touches Taichi). Springs are an edge list with a
per-spring ``kind`` (structural, shear, bend, body diagonal); rest lengths are the initial
distances. ``pinned`` lists node indices held at their target positions. ``triangles`` is the
render surface (cloth quads split in two, the outer faces of a jelly lattice), oriented outward
for closed surfaces.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

STRUCTURAL, SHEAR, BEND, BODY = 0, 1, 2, 3
KIND_NAMES = ("structural", "shear", "bend", "body")


@dataclass
class Topology:
    positions: np.ndarray  # (N, 3) float64, m
    masses: np.ndarray  # (N,) kg
    edges: np.ndarray  # (M, 2) int32
    rest_length: np.ndarray  # (M,) m
    ks: np.ndarray  # (M,) N/m
    kd: np.ndarray  # (M,) N·s/m
    kind: np.ndarray  # (M,) int8, one of STRUCTURAL, SHEAR, BEND, BODY
    pinned: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int32))
    tets: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int32))  # volume elements

    def __post_init__(self):
        self.positions = np.asarray(self.positions, np.float64).reshape(-1, 3)
        n = len(self.positions)
        self.masses = np.broadcast_to(np.asarray(self.masses, np.float64), (n,)).copy()
        self.edges = np.asarray(self.edges, np.int32).reshape(-1, 2)
        m = len(self.edges)
        for name in ("rest_length", "ks", "kd"):
            setattr(self, name, np.broadcast_to(np.asarray(getattr(self, name), np.float64), (m,)).copy())
        self.kind = np.broadcast_to(np.asarray(self.kind, np.int8), (m,)).copy()
        self.pinned = np.unique(np.asarray(self.pinned, np.int32).ravel())
        self.triangles = np.asarray(self.triangles, np.int32).reshape(-1, 3)
        self.tets = np.asarray(self.tets, np.int32).reshape(-1, 4)
        if np.any(self.masses <= 0):
            raise ValueError("masses: every node needs a positive mass (pin a node to fix it)")
        if m and (self.edges.min() < 0 or self.edges.max() >= n or np.any(self.edges[:, 0] == self.edges[:, 1])):
            raise ValueError("edges: node index out of range or a spring joins a node to itself")
        if len(self.pinned) and (self.pinned[0] < 0 or self.pinned[-1] >= n):
            raise ValueError("pinned: node index out of range")

    @property
    def node_count(self) -> int:
        return len(self.positions)

    @property
    def spring_count(self) -> int:
        return len(self.edges)

    def count(self, kind: int) -> int:
        return int(np.count_nonzero(self.kind == kind))


def _springs(pos, pairs, kinds, ks, kd):
    pairs = np.asarray(pairs, np.int32).reshape(-1, 2)
    rest = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
    return pairs, rest, np.asarray(ks, np.float64) * np.ones(len(pairs)), \
        np.asarray(kd, np.float64) * np.ones(len(pairs)), np.asarray(kinds, np.int8)


def _build(pos, mass, groups, pinned=(), triangles=()):
    """groups: list of (pairs, kind, ks, kd)."""
    pos = np.asarray(pos, np.float64)
    parts = [_springs(pos, p, np.full(len(p), k), ks, kd) for p, k, ks, kd in groups if len(p)]
    cat = (lambda i, empty: np.concatenate([p[i] for p in parts]) if parts else empty)
    return Topology(pos, mass, cat(0, np.zeros((0, 2), np.int32)), cat(1, np.zeros(0)),
                    cat(2, np.zeros(0)), cat(3, np.zeros(0)), cat(4, np.zeros(0, np.int8)),
                    pinned, triangles)


def chain(n: int, start=(0.0, 0.0, 0.0), end=None, length: float = 1.0, direction=(0.0, -1.0, 0.0),
          mass: float = 0.01, ks: float = 1e3, kd: float = 0.0, bend_ks: float = 0.0,
          bend_kd: float = 0.0, pin_start: bool = True) -> Topology:
    """n nodes on the segment start→end (or start + length·direction), springs i–i+1, optional
    bending springs i–i+2 (when bend_ks > 0). The first node is pinned unless ``pin_start`` is False."""
    if n < 2:
        raise ValueError("chain: n must be >= 2")
    start = np.asarray(start, np.float64)
    if end is None:
        d = np.asarray(direction, np.float64)
        end = start + length * d / np.linalg.norm(d)
    pos = start + np.linspace(0.0, 1.0, n)[:, None] * (np.asarray(end, np.float64) - start)
    i = np.arange(n - 1)
    groups = [(np.stack([i, i + 1], 1), STRUCTURAL, ks, kd)]
    if bend_ks > 0 and n > 2:
        j = np.arange(n - 2)
        groups.append((np.stack([j, j + 2], 1), BEND, bend_ks, bend_kd))
    return _build(pos, mass, groups, [0] if pin_start else [])


def line_roots(start, end, count: int) -> np.ndarray:
    """``count`` hair roots evenly spaced on the segment start→end."""
    t = np.linspace(0.0, 1.0, count)[:, None]
    return np.asarray(start, np.float64) + t * (np.asarray(end, np.float64) - np.asarray(start, np.float64))


def scalp_roots(center, radius: float, count: int, cap_angle: float = 1.0, axis=(0.0, 1.0, 0.0)):
    """``count`` roots on a spherical cap (half-angle ``cap_angle`` rad around ``axis``) laid out
    on a Fibonacci spiral; returns (roots, outward unit normals) for :func:`hair`."""
    k = np.arange(count) + 0.5
    cos_t = 1.0 - (1.0 - np.cos(cap_angle)) * k / count
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    local = np.stack([sin_t * np.cos(phi), cos_t, sin_t * np.sin(phi)], 1)
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    # rotate +y onto axis (Rodrigues); axis = -y handled by a flip
    y = np.array([0.0, 1.0, 0.0])
    v, c = np.cross(y, a), float(y @ a)
    if c < -1 + 1e-12:
        R = np.diag([1.0, -1.0, -1.0])
    else:
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        R = np.eye(3) + vx + vx @ vx / (1.0 + c)
    normals = local @ R.T
    return np.asarray(center, np.float64) + radius * normals, normals


def hair(roots, directions=(0.0, -1.0, 0.0), length: float = 0.3, segments: int = 10,
         mass: float = 0.001, ks: float = 1e3, kd: float = 0.0, bend_ks: float = 10.0,
         bend_kd: float = 0.0) -> Topology:
    """One strand per root, grown along its direction (one vector or one per root): segments + 1
    nodes, the root pinned, stretch springs i–i+1 and bending springs i–i+2."""
    roots = np.asarray(roots, np.float64).reshape(-1, 3)
    dirs = np.broadcast_to(np.asarray(directions, np.float64), roots.shape)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    strands = [chain(segments + 1, r, r + length * d, mass=mass, ks=ks, kd=kd, bend_ks=bend_ks,
                     bend_kd=bend_kd) for r, d in zip(roots, dirs)]
    return merge(*strands)


def _grid_pairs(nx, ny, di, dj):
    """Index pairs (j*nx + i, (j+dj)*nx + i+di) over the grid where both ends exist."""
    i0, i1 = max(0, -di), nx - max(0, di)
    j0, j1 = max(0, -dj), ny - max(0, dj)
    jj, ii = np.meshgrid(np.arange(j0, j1), np.arange(i0, i1), indexing="ij")
    a = (jj * nx + ii).ravel()
    return np.stack([a, a + dj * nx + di], 1)


def _quads_to_triangles(q00, q10, q11, q01):
    return np.concatenate([np.stack([q00, q10, q11], -1).reshape(-1, 3),
                           np.stack([q00, q11, q01], -1).reshape(-1, 3)])


def cloth(nx: int, ny: int, size=(1.0, 1.0), origin=(0.0, 0.0, 0.0), plane: str = "xz",
          mass: float = 0.01, ks: float = 1e4, kd: float = 0.0, shear_ks=None, bend_ks=None,
          shear_kd=None, bend_kd=None, pin="none") -> Topology:
    """An nx × ny grid, node j*nx + i at origin + i·dx·u + j·dy·w with (u, w) = (x, z) for
    ``plane="xz"`` (horizontal), (x, y) for ``"xy"`` (hanging, facing z) or (z, y) for ``"zy"``
    (hanging, facing x: a flag across a wind along x). Structural springs to the 4
    neighbours, shear to the diagonals, bend to the second neighbours (shear/bend stiffness default
    to ks and ks/10). ``pin``: "none", "corners" (the two corners of row ny−1), "top" (row ny−1) or
    a list of node indices."""
    if nx < 2 or ny < 2:
        raise ValueError("cloth: nx and ny must be >= 2")
    u, w = {"xz": ((1, 0, 0), (0, 0, 1)), "xy": ((1, 0, 0), (0, 1, 0)), "zy": ((0, 0, 1), (0, 1, 0))}[plane]
    jj, ii = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    fi, fj = (ii / (nx - 1) * size[0]).ravel(), (jj / (ny - 1) * size[1]).ravel()
    pos = np.asarray(origin, np.float64) + fi[:, None] * np.asarray(u, float) + fj[:, None] * np.asarray(w, float)
    shear_ks = ks if shear_ks is None else shear_ks
    bend_ks = 0.1 * ks if bend_ks is None else bend_ks
    shear_kd = kd if shear_kd is None else shear_kd
    bend_kd = 0.1 * kd if bend_kd is None else bend_kd
    groups = [(np.concatenate([_grid_pairs(nx, ny, 1, 0), _grid_pairs(nx, ny, 0, 1)]), STRUCTURAL, ks, kd),
              (np.concatenate([_grid_pairs(nx, ny, 1, 1), _grid_pairs(nx, ny, -1, 1)]), SHEAR, shear_ks, shear_kd),
              (np.concatenate([_grid_pairs(nx, ny, 2, 0), _grid_pairs(nx, ny, 0, 2)]), BEND, bend_ks, bend_kd)]
    top = (ny - 1) * nx
    if isinstance(pin, str):
        pinned = {"none": [], "corners": [top, top + nx - 1], "top": list(range(top, top + nx))}[pin]
    else:
        pinned = list(pin)
    q = _grid_pairs(nx, ny, 1, 1)[:, 0]  # lower-left corner of each quad
    tris = _quads_to_triangles(q, q + 1, q + nx + 1, q + nx)
    return _build(pos, mass, groups, pinned, tris)


def jelly(nx: int, ny: int, nz: int, size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), mass: float = 0.01,
          ks: float = 1e3, kd: float = 0.0, shear_ks=None, body_ks=None, pinned=()) -> Topology:
    """A 3-D lattice, node (k*ny + j)*nx + i: axis springs (structural), both diagonals of every
    cell face (shear) and the 4 body diagonals of every cell (body). Triangles: the outer faces."""
    if min(nx, ny, nz) < 2:
        raise ValueError("jelly: nx, ny and nz must be >= 2")
    shape = (nz, ny, nx)
    kk, jj, ii = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    frac = np.stack([ii / (nx - 1), jj / (ny - 1), kk / (nz - 1)], -1).reshape(-1, 3)
    pos = np.asarray(origin, np.float64) + frac * np.asarray(size, np.float64)
    idx = np.arange(nx * ny * nz).reshape(shape)

    def pairs(offsets):
        out = []
        for dk, dj, di in offsets:
            src = idx[max(0, -dk):nz - max(0, dk), max(0, -dj):ny - max(0, dj), max(0, -di):nx - max(0, di)]
            out.append(np.stack([src.ravel(), src.ravel() + (dk * ny + dj) * nx + di], 1))
        return np.concatenate(out)

    axis = [(0, 0, 1), (0, 1, 0), (1, 0, 0)]
    face = [(0, 1, 1), (0, 1, -1), (1, 0, 1), (1, 0, -1), (1, 1, 0), (1, -1, 0)]
    body = [(1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)]
    shear_ks = ks if shear_ks is None else shear_ks
    body_ks = ks if body_ks is None else body_ks
    groups = [(pairs(axis), STRUCTURAL, ks, kd), (pairs(face), SHEAR, shear_ks, kd), (pairs(body), BODY, body_ks, kd)]
    top = _build(pos, mass, groups, pinned, _box_surface(idx, pos))
    top.tets = box_tets(nx, ny, nz, pos)  # for volume terms (engine.forces.elements)
    return top


def _box_surface(idx, pos):
    """Outward triangles of the six sides of a node lattice ``idx`` (nz, ny, nx)."""
    tris = []
    for sl in [np.s_[0], np.s_[-1]]:  # the six sides as 2-D index grids, quads split in two
        for side in (idx[sl], idx[:, sl], idx[:, :, sl]):
            tris.append(_quads_to_triangles(side[:-1, :-1], side[:-1, 1:], side[1:, 1:], side[1:, :-1]))
    tris = np.concatenate(tris)
    centre = pos.mean(0)  # orient outward: flip triangles whose normal points at the centre
    p0, p1, p2 = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), (p0 + p1 + p2) / 3 - centre) < 0
    tris[inward] = tris[inward][:, ::-1]
    return tris


def solid(nx: int, ny: int, nz: int, size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0),
          density: float = 1000.0, pinned=()) -> Topology:
    """An elastic box: an nx × ny × nz node lattice (node (k·ny + j)·nx + i) of ``size`` (m) from
    ``origin`` cut into 6 tetrahedra per cell (:func:`box_tets`), no springs; each node carries a
    quarter of the mass ρV of every tet it belongs to (lumped mass, kg; ``density`` in kg/m³).
    Triangles: the outer faces."""
    if min(nx, ny, nz) < 2:
        raise ValueError(f"resolution: a solid needs at least 2 nodes per axis to make a tetrahedron, got {[nx, ny, nz]}")
    kk, jj, ii = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    frac = np.stack([ii / (nx - 1), jj / (ny - 1), kk / (nz - 1)], -1).reshape(-1, 3)
    pos = np.asarray(origin, np.float64) + frac * np.asarray(size, np.float64)
    tets = box_tets(nx, ny, nz, pos)
    vol = tet_volumes(pos, tets)
    mass = np.zeros(len(pos))
    for s in range(4):
        mass += np.bincount(tets[:, s], density * vol / 4.0, len(pos))
    idx = np.arange(nx * ny * nz).reshape(nz, ny, nx)
    return Topology(pos, mass, np.zeros((0, 2), np.int32), np.zeros(0), np.zeros(0), np.zeros(0),
                    np.zeros(0, np.int8), pinned, _box_surface(idx, pos), tets)


def tet_volumes(x, tets) -> np.ndarray:
    """Signed volumes (m³) of tetrahedra (T, 4) over positions x (N, 3)."""
    x = np.asarray(x, np.float64)
    a = x[tets[:, 0]]
    return np.einsum("ij,ij->i", x[tets[:, 1]] - a, np.cross(x[tets[:, 2]] - a, x[tets[:, 3]] - a)) / 6.0


def merge(*tops: Topology) -> Topology:
    """Several bodies in one topology: node indices of later bodies are offset."""
    if not tops:
        raise ValueError("merge: need at least one topology")
    offs = np.cumsum([0] + [t.node_count for t in tops[:-1]])
    cat = lambda name: np.concatenate([getattr(t, name) for t in tops])  # noqa: E731
    return Topology(cat("positions"), cat("masses"),
                    np.concatenate([t.edges + o for t, o in zip(tops, offs)]), cat("rest_length"),
                    cat("ks"), cat("kd"), cat("kind"),
                    np.concatenate([t.pinned + o for t, o in zip(tops, offs)]),
                    np.concatenate([t.triangles + o for t, o in zip(tops, offs)]),
                    np.concatenate([t.tets + o for t, o in zip(tops, offs)]))


def surface_lines(top: Topology, kinds: Sequence[int] = (STRUCTURAL,)) -> np.ndarray:
    """(K, 2) node index pairs of the springs of the given kinds, for line rendering."""
    return top.edges[np.isin(top.kind, kinds)]


def hinges(triangles: np.ndarray) -> np.ndarray:
    """(H, 4) hinges (a, b, c, d) of a triangle mesh: every edge a–b shared by exactly two
    triangles (a, b, c) and (b, a, d) of consistent orientation, in sorted-edge order."""
    tris = np.asarray(triangles, np.int64).reshape(-1, 3)
    found = {}
    for t in tris.tolist():
        for s in range(3):
            a, b, c = t[s], t[(s + 1) % 3], t[(s + 2) % 3]
            found.setdefault((min(a, b), max(a, b)), []).append((a, b, c))
    out = []
    for key in sorted(found):
        side = found[key]
        if len(side) == 2:
            (a, b, c), (_, _, d) = side
            out.append((a, b, c, d))
    return np.asarray(out, np.int32).reshape(-1, 4)


def box_tets(nx: int, ny: int, nz: int, positions: np.ndarray) -> np.ndarray:
    """(6 (nx−1)(ny−1)(nz−1), 4) tetrahedra of a node lattice (node (k·ny + j)·nx + i): each cell
    cut in six around its main diagonal (Kuhn's subdivision: neighbouring cells share their face
    diagonals, so the mesh is conforming), every tet oriented to positive volume."""
    if min(nx, ny, nz) < 2:
        raise ValueError(f"resolution: needs at least 2 nodes per axis to make a tetrahedron, got {[nx, ny, nz]}")
    kk, jj, ii = np.meshgrid(np.arange(nz - 1), np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    base = ((kk * ny + jj) * nx + ii).ravel()
    corner = lambda di, dj, dk: base + (dk * ny + dj) * nx + di  # noqa: E731
    v000, v111 = corner(0, 0, 0), corner(1, 1, 1)
    tets = []
    for p, q in (((1, 0, 0), (1, 1, 0)), ((1, 0, 0), (1, 0, 1)), ((0, 1, 0), (1, 1, 0)),
                 ((0, 1, 0), (0, 1, 1)), ((0, 0, 1), (1, 0, 1)), ((0, 0, 1), (0, 1, 1))):
        tets.append(np.stack([v000, corner(*p), corner(*q), v111], 1))
    tets = np.concatenate(tets).astype(np.int32)
    flip = tet_volumes(positions, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return tets

"""Model (fixed topology and parameters) and State (positions, velocities) as struct-of-arrays fields.

Allocated once from a :class:`~engine.springs.topology.Topology`. Besides the per-spring and
per-node parameters the model holds two precomputed orderings, both built once in numpy:

* a CSR adjacency (``adj_offset``, ``adj_spring``, ``adj_sign``): for each node its incident
  springs in increasing index and +1/−1 for end a/b. Forces are gathered per node in that fixed
  order, so results are bit-identical run to run (no atomics).
* a greedy edge colouring (``color_spring`` grouped by ``color_ranges``): no two springs of one
  colour share a node, so a colour can be projected in parallel without races (XPBD, distance
  limits) and Gauss–Seidel sweeps stay deterministic.
"""
import numpy as np
import taichi as ti

from ..geometry.colouring import greedy_colors, schedule
from .topology import Topology
from ..launch import data_oriented


def csr_adjacency(n_nodes: int, edges: np.ndarray):
    """(offset (N+1,), spring (2M,), sign (2M,)): node i's springs are spring[offset[i]:offset[i+1]]."""
    m = len(edges)
    ends = np.concatenate([edges[:, 0], edges[:, 1]]).astype(np.int64)
    springs = np.concatenate([np.arange(m), np.arange(m)])
    sign = np.concatenate([np.ones(m), -np.ones(m)])
    order = np.lexsort((springs, ends))
    offset = np.zeros(n_nodes + 1, np.int64)
    np.cumsum(np.bincount(ends, minlength=n_nodes), out=offset[1:])
    return offset.astype(np.int32), springs[order].astype(np.int32), sign[order]


def edge_coloring(n_nodes: int, edges: np.ndarray):
    """Greedy colouring in spring order (deterministic). Returns (colour per spring, n_colours)."""
    return greedy_colors(n_nodes, edges)


@data_oriented
class SpringModel:
    """Fields (dtype is f32 for the engine; f64 for tests):

    node_mass, node_inv_mass (0 for pinned nodes), node_pinned (i32), pin_start / pin_target
    (where a pinned node is at the start / end of the current frame); spring_a, spring_b,
    spring_rest_length, spring_ks, spring_kd;
    adj_offset, adj_spring, adj_sign; color_spring (springs grouped by colour, ranges in
    color_ranges). Passed to the module-level kernels as a template argument (its counts are
    compile-time constants there). Gravity is an input (engine.control), not part of the model.
    """

    def __init__(self, top: Topology, dtype=ti.f32):
        self.top, self.dtype = top, dtype
        self.node_count = n = top.node_count
        self.spring_count = m = top.spring_count
        N, M = max(1, n), max(1, m)
        self.node_mass = ti.field(dtype, N)
        self.node_inv_mass = ti.field(dtype, N)
        self.node_pinned = ti.field(ti.i32, N)
        self.pin_start = ti.Vector.field(3, dtype, N)
        self.pin_target = ti.Vector.field(3, dtype, N)
        self.spring_a = ti.field(ti.i32, M)
        self.spring_b = ti.field(ti.i32, M)
        self.spring_rest_length = ti.field(dtype, M)
        self.spring_ks = ti.field(dtype, M)
        self.spring_kd = ti.field(dtype, M)
        self.adj_offset = ti.field(ti.i32, N + 1)
        self.adj_spring = ti.field(ti.i32, 2 * M)
        self.adj_sign = ti.field(dtype, 2 * M)
        self.color_spring = ti.field(ti.i32, M)

        npd = np.float64 if dtype == ti.f64 else np.float32
        pad = lambda a, size, t: np.concatenate([np.asarray(a, t), np.zeros(size - len(a), t)])  # noqa: E731
        self.node_mass.from_numpy(pad(top.masses, N, npd))
        self.pinned_mask = np.zeros(n, bool)
        self.pinned_mask[top.pinned] = True
        self._write_inv_mass()
        self.node_pinned.from_numpy(pad(self.pinned_mask.astype(np.int32), N, np.int32))
        p = np.zeros((N, 3), npd)
        p[:n] = top.positions
        self.pin_start.from_numpy(p)
        self.pin_target.from_numpy(p)
        self.spring_a.from_numpy(pad(top.edges[:, 0], M, np.int32))
        self.spring_b.from_numpy(pad(top.edges[:, 1], M, np.int32))
        self.spring_rest_length.from_numpy(pad(top.rest_length, M, npd))
        self.spring_ks.from_numpy(pad(top.ks, M, npd))
        self.spring_kd.from_numpy(pad(top.kd, M, npd))
        off, spr, sign = csr_adjacency(n, top.edges)
        self.adj_offset.from_numpy(pad(off, N + 1, np.int32))
        self.adj_spring.from_numpy(pad(spr, 2 * M, np.int32))
        self.adj_sign.from_numpy(pad(sign, 2 * M, npd))
        self.spring_colors, nc = colors, nc = edge_coloring(n, top.edges)
        order, self.color_ranges = schedule(colors, nc)
        self.color_spring.from_numpy(pad(order, M, np.int32))

    def _write_inv_mass(self):
        inv = np.where(self.pinned_mask, 0.0, 1.0 / self.top.masses)
        N = max(1, self.node_count)
        buf = np.zeros(N, np.float64 if self.dtype == ti.f64 else np.float32)
        buf[: self.node_count] = inv
        self.node_inv_mass.from_numpy(buf)

    def set_pinned(self, node: int, pinned: bool) -> None:
        self.pinned_mask[node] = pinned
        self.node_pinned[node] = int(pinned)
        self.node_inv_mass[node] = 0.0 if pinned else 1.0 / float(self.top.masses[node])

    def free_masses(self) -> np.ndarray:
        return self.top.masses[~self.pinned_mask]


@data_oriented
class SpringState:
    """node_pos (m) and node_vel (m/s), one vector per node."""

    def __init__(self, n: int, dtype=ti.f32):
        self.dtype = dtype
        self.node_pos = ti.Vector.field(3, dtype, max(1, n))
        self.node_vel = ti.Vector.field(3, dtype, max(1, n))

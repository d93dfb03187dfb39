"""Distance limits for inextensible hair and chains: |x_a − x_b| ≤ (1 + max_stretch)·rest.

Mass-weighted Gauss–Seidel converges slowly along a chain (each fix re-stretches the neighbours),
so springs are swept outward from the pins, "follow the leader" style (Müller et al. 2012, *Fast
Simulation of Inextensible Hair and Fur*): each structural spring gets the end nearer to a pin
(BFS depth) as parent, and only the child is moved onto the cap — one pass caps a tree (hair, a
chain) exactly. Springs are grouped by (child depth, colour) so each launch is race-free and the
result deterministic. Springs not reachable from a pin (free bodies) or with both ends at equal
depth split the correction by inverse mass. After the position fix the separating part of the
child's velocity along the spring is removed (inelastic: energy never grows).
"""
from collections import deque

import numpy as np
import taichi as ti

from .model import SpringModel, SpringState

CHILD_B, CHILD_A, SPLIT = 0, 1, 2


def limit_schedule(model: SpringModel):
    """(spring order, mode per spring in that order, [(lo, hi), ...] launch ranges)."""
    top = model.top
    sel = np.nonzero(top.kind == 0)[0]
    n = top.node_count
    depth = np.full(n, -1, np.int64)
    nbrs = [[] for _ in range(n)]
    for a, b in top.edges[sel].tolist():
        nbrs[a].append(b)
        nbrs[b].append(a)
    queue = deque(np.nonzero(model.pinned_mask)[0].tolist())
    depth[list(queue)] = 0
    while queue:
        u = queue.popleft()
        for v in nbrs[u]:
            if depth[v] < 0:
                depth[v] = depth[u] + 1
                queue.append(v)
    da, db = depth[top.edges[sel, 0]], depth[top.edges[sel, 1]]
    mode = np.where((da < 0) | (db < 0) | (da == db), SPLIT, np.where(da < db, CHILD_B, CHILD_A))
    level = np.where(mode == SPLIT, n + 1, np.maximum(da, db))
    colors = model.spring_colors[sel]
    order = np.lexsort((sel, colors, level))
    keys = np.stack([level[order], colors[order]], 1)
    starts = np.nonzero(np.any(np.diff(keys, axis=0) != 0, axis=1))[0] + 1 if len(order) else []
    bounds = [0] + list(starts) + [len(order)]
    ranges = [(int(lo), int(hi)) for lo, hi in zip(bounds[:-1], bounds[1:]) if hi > lo]
    return sel[order].astype(np.int32), mode[order].astype(np.int32), ranges


@ti.kernel
def _project(model: ti.template(), state: ti.template(), lim_spring: ti.template(), lim_mode: ti.template(),
             lo: ti.i32, hi: ti.i32, max_stretch: ti.f64):
    X, V, w = ti.static(state.node_pos, state.node_vel, model.node_inv_mass)
    sa, sb, rl = ti.static(model.spring_a, model.spring_b, model.spring_rest_length)
    for q in range(lo, hi):
        s, mode = lim_spring[q], lim_mode[q]
        a, b = sa[s], sb[s]
        wa, wb = w[a], w[b]
        one, zero = ti.cast(1, model.dtype), ti.cast(0, model.dtype)
        if mode == CHILD_B:
            wa, wb = zero, ti.select(wb > 0, one, zero)
        elif mode == CHILD_A:
            wa, wb = ti.select(wa > 0, one, zero), zero
        L = X[a] - X[b]
        ln = L.norm()
        cap = (1 + ti.cast(max_stretch, model.dtype)) * rl[s]
        if ln > cap and wa + wb > 0:
            nrm = L / ln
            corr = (ln - cap) / (wa + wb) * nrm
            X[a] -= wa * corr
            X[b] += wb * corr
            rel = (V[a] - V[b]).dot(nrm)
            if rel > 0:
                imp = rel / (wa + wb) * nrm
                V[a] -= wa * imp
                V[b] += wb * imp


class DistanceLimits:
    """The sweep schedule of a network's structural springs and its launcher."""

    def __init__(self, model: SpringModel, state: SpringState):
        M = max(1, model.spring_count)
        self.model, self.state = model, state
        self.lim_spring = ti.field(ti.i32, M)
        self.lim_mode = ti.field(ti.i32, M)
        self.refresh()

    def refresh(self) -> None:
        """Rebuild the sweep order (after pins change)."""
        order, mode, self.ranges = limit_schedule(self.model)
        M = max(1, self.model.spring_count)
        pad = lambda a: np.concatenate([a, np.zeros(M - len(a), np.int32)])  # noqa: E731
        self.lim_spring.from_numpy(pad(order))
        self.lim_mode.from_numpy(pad(mode))

    def apply(self, max_stretch: float, passes: int) -> None:
        for _ in range(passes):
            for lo, hi in self.ranges:
                _project(self.model, self.state, self.lim_spring, self.lim_mode, lo, hi, max_stretch)

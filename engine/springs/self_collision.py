"""Self-collision of a soft body: node–node contact at the body's thickness through the shared
deterministic neighbour grid (engine.geometry.grid), after each step.

Each node is a sphere of radius ``thickness``: two nodes closer than 2·thickness that no spring
joins are pushed apart along their line of centres, each by its share of the overlap weighted by
inverse mass (w_i / (w_i + w_j): pinned nodes, w = 0, do not move and take none of it), in
``iterations`` Jacobi sweeps (per-node gathers, no float atomics: the same bytes for any thread
count; each pair's correction is antisymmetric, so momentum is kept). Velocities take the
corrections (v += Δx/h, the position-based update), which makes the contact inelastic. The
colliders are applied after this, by the body's own step (they win over self-contact).
"""
import taichi as ti

from ..geometry.grid import HashGrid
from ..launch import data_oriented

RELAX = 1.0  # Jacobi relaxation: a fixed factor (not 1/contact count) keeps each pair antisymmetric


@data_oriented
class SelfCollision:
    """``model``/``state``: the body's SpringModel and SpringState; ``thickness`` in m."""

    def __init__(self, model, state, thickness: float, iterations: int = 6):
        self.model, self.state = model, state
        self.n = max(1, model.node_count)
        self.d = 2.0 * float(thickness)
        self.iterations = int(iterations)
        self.grid = HashGrid(self.n, self.d)
        self.member = ti.field(ti.i32, shape=self.n)
        self.member.fill(1)
        dt = model.dtype
        self.corr = ti.Vector.field(3, dt, shape=self.n)
        self.delta = ti.Vector.field(3, dt, shape=self.n)

    def apply(self, h: float) -> None:
        self.grid.build(self.state.node_pos, self.member)
        self.corr.fill(0)
        for _ in range(self.iterations):
            self.sweep()
        self.finish(h)

    @ti.func
    def _joined(self, i, j):
        """Whether a spring joins nodes i and j (i's adjacency list)."""
        M = self.model
        found = 0
        for k in range(M.adj_offset[i], M.adj_offset[i + 1]):
            s = M.adj_spring[k]
            if M.spring_a[s] == j or M.spring_b[s] == j:
                found = 1
        return found

    @ti.func
    def _contact(self, j, i, xi, wi, dx: ti.template()):
        """Node j's push on node i (at xi, inverse mass wi > 0) when closer than d and unjoined,
        added into dx."""
        r = xi - self.state.node_pos[j]
        d2 = r.dot(r)
        if 0 < d2 < self.d * self.d:
            if self._joined(i, j) == 0:
                d = ti.sqrt(d2)
                dx += wi / (wi + self.model.node_inv_mass[j]) * (self.d - d) / d * r

    @ti.kernel
    def sweep(self):
        M, S = self.model, self.state
        for i in range(self.n):
            wi = M.node_inv_mass[i]
            dx = ti.Vector.zero(M.dtype, 3)
            if wi > 0:
                xi = S.node_pos[i]
                self.grid.for_neighbours(i, self.member, 1, self._contact, (i, xi, wi, dx))
            self.delta[i] = RELAX * dx
        for i in range(self.n):
            S.node_pos[i] += self.delta[i]
            self.corr[i] += self.delta[i]

    @ti.kernel
    def finish(self, h: ti.f64):
        for i in range(self.n):
            self.state.node_vel[i] += self.corr[i] / ti.cast(h, self.model.dtype)
